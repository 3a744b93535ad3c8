"""Calibration constants of :mod:`service.localization.confidence` (generated).

Provenance: written by ``python -m bench.trust --fit`` (see that module); the fit uses
only the tuning seeds named in :data:`PROVENANCE`, the bench reports on other seeds.
"""

PROVENANCE = {'command': 'python -m bench.trust --fit --slow-stride 1 --save-data '
            '/tmp/i12_tune_s1.json',
 'tuning_seeds': [100, 102, 101]}

#: k_metric of ``cov = k * max(s^2, f) * (J^T W J)^-1`` (``bench.trust._scale_for``: the
#: smallest and largest mean NEES over the 5 / 10 / 20 cm operating points and the two detector
#: settings of the tuning frames centred on 6).
COVARIANCE_SCALE = {'level_set': 2.848978,
 'algebraic': 3.015399,
 'frobenius': 2.991939,
 'wasserstein': 0.457207,
 'bhattacharyya': 0.382418,
 'bbox': 0.448892,
 'qbbox': 0.579907,
 'iou': 0.379732,
 'giou': 0.364594}

#: f_metric: floor of the a-posteriori variance factor (``bench.trust.S2_FLOOR_QUANTILE`` of
#: the tuning frames' s^2).
S2_FLOOR = {'iou': 0.033622,
 'giou': 0.034747,
 'bbox': 558.695241,
 'qbbox': 414.453205,
 'algebraic': 18526189.938227,
 'frobenius': 21995197.715379,
 'wasserstein': 270.064654,
 'bhattacharyya': 0.022344,
 'level_set': 3.007476}

#: Runner-up / best score (sum of inlier IoUs) at and above which an answer is ambiguous.
AMBIGUITY_RATIO = 0.9

#: The same ratio for a runner-up matching the same map objects (``confidence.is_ambiguous``).
AMBIGUITY_RATIO_SAME_OBJECTS = 0.95

#: Default ``LocalizationOptions.min_confidence``.
MIN_CONFIDENCE = 0.16

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
CONFIDENCE_MODELS = {'refined': {'intercept': -9.734932,
             'coef': {'inliers_ge3': 0.000527,
                      'inliers_ge4': -1.308263,
                      'log_inliers': 0.853441,
                      'inlier_fraction': 8.354629,
                      'mean_iou': 1.839118,
                      'log_s2': -1.165828,
                      'logit_gauss': 0.41015,
                      'margin': -0.488576,
                      'log_samples': -0.09021,
                      'chi2_competitor': 0.106407},
             'metric_offset': {'algebraic': 1.154759,
                               'bbox': 0.082036,
                               'bhattacharyya': -0.154024,
                               'frobenius': 1.134789,
                               'giou': 1.160445,
                               'iou': 1.172629,
                               'qbbox': 0.242912,
                               'wasserstein': 0.231601}},
 'none': {'intercept': -16.363322,
          'coef': {'inliers_ge3': 3.785562,
                   'inliers_ge4': 1.906768,
                   'log_inliers': 3.881419,
                   'inlier_fraction': 0.003912,
                   'mean_iou': 11.037241,
                   'margin': 0.231842,
                   'log_samples': -0.969745}}}
