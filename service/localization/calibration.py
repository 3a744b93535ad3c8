"""Calibration constants of :mod:`service.localization.confidence` (generated).

Provenance: written by ``python -m bench.trust --fit`` (see that module); the fit uses
only the tuning seeds named in :data:`PROVENANCE`, the bench reports on other seeds.
"""

PROVENANCE = {'command': 'python -m bench.trust --fit --save-data /tmp/tune_final2.json',
 'tuning_seeds': [100, 102, 101]}

#: k_metric of ``cov = k * max(s^2, f) * (J^T W J)^-1`` (``bench.trust._scale_for``: the
#: smallest and largest mean NEES over the 5 / 10 / 20 cm operating points and the two detector
#: settings of the tuning frames centred on 6).
COVARIANCE_SCALE = {'level_set': 2.846803,
 'algebraic': 3.015398,
 'frobenius': 2.991939,
 'wasserstein': 0.457207,
 'bhattacharyya': 0.382418,
 'bbox': 0.449106,
 'qbbox': 0.580953,
 'iou': 0.381245,
 'giou': 0.362179}

#: f_metric: floor of the a-posteriori variance factor (``bench.trust.S2_FLOOR_QUANTILE`` of
#: the tuning frames' s^2).
S2_FLOOR = {'iou': 0.033771,
 'giou': 0.034747,
 'bbox': 558.366407,
 'qbbox': 413.61146,
 'algebraic': 18526189.938227,
 'frobenius': 21995197.715379,
 'wasserstein': 270.064654,
 'bhattacharyya': 0.022344,
 'level_set': 3.010206}

#: Runner-up / best score (sum of inlier IoUs) at and above which an answer is ambiguous.
AMBIGUITY_RATIO = 0.9

#: The same ratio for a runner-up matching the same map objects (``confidence.is_ambiguous``).
AMBIGUITY_RATIO_SAME_OBJECTS = 0.95

#: Default ``LocalizationOptions.min_confidence``.
MIN_CONFIDENCE = 0.17

#: Features of the confidence model (``confidence.evidence_features``), in order.
CONFIDENCE_FEATURES = ('inliers_ge3',
 'inliers_ge4',
 'log_inliers',
 'inlier_fraction',
 'mean_iou',
 'log_s2',
 'logit_gauss',
 'margin',
 'log_samples',
 'chi2_competitor')

#: Logistic models: P = 1 / (1 + exp(-(intercept + sum coef * feature))).
CONFIDENCE_MODELS = {'refined': {'intercept': -10.145605,
             'coef': {'inliers_ge3': 0.002224,
                      'inliers_ge4': -1.324987,
                      'log_inliers': 0.742133,
                      'inlier_fraction': 9.172052,
                      'mean_iou': 1.578925,
                      'log_s2': -1.193167,
                      'logit_gauss': 0.419335,
                      'margin': -0.511102,
                      'log_samples': -0.083693,
                      'chi2_competitor': 0.092807},
             'metric_offset': {'algebraic': 1.22149,
                               'bbox': 0.092336,
                               'bhattacharyya': -0.154151,
                               'frobenius': 1.174197,
                               'giou': 1.179336,
                               'iou': 1.163206,
                               'qbbox': 0.253965,
                               'wasserstein': 0.243669}},
 'none': {'intercept': -16.576849,
          'coef': {'inliers_ge3': 3.786856,
                   'inliers_ge4': 1.929234,
                   'log_inliers': 3.833601,
                   'inlier_fraction': 0.003608,
                   'mean_iou': 11.306512,
                   'margin': 0.24305,
                   'log_samples': -0.951828}}}
