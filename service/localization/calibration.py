"""Calibration constants of :mod:`service.localization.confidence` (generated).

Provenance: written by ``python -m bench.trust --fit`` (see that module); the fit uses
only the tuning seeds named in :data:`PROVENANCE`, the bench reports on other seeds.
"""

PROVENANCE = {'command': 'python -m bench.trust --fit --save-data /tmp/tune_merged.json',
 'tuning_seeds': [100, 102, 101]}

#: k_metric of ``cov = k * max(s^2, f) * (J^T W J)^-1`` (``bench.trust._scale_for``: the
#: smallest and largest mean NEES over the 5 / 10 / 20 cm operating points and the two detector
#: settings of the tuning frames centred on 6).
COVARIANCE_SCALE = {'level_set': 2.846795,
 'algebraic': 3.058089,
 'frobenius': 3.025347,
 'wasserstein': 0.457436,
 'bhattacharyya': 0.38358,
 'bbox': 0.445323,
 'qbbox': 0.569374,
 'iou': 0.457738,
 'giou': 0.447407}

#: f_metric: floor of the a-posteriori variance factor (``bench.trust.S2_FLOOR_QUANTILE`` of
#: the tuning frames' s^2).
S2_FLOOR = {'iou': 0.029512,
 'giou': 0.029843,
 'bbox': 560.571326,
 'qbbox': 418.231977,
 'algebraic': 18052346.834332,
 'frobenius': 21528570.24772,
 'wasserstein': 270.064654,
 'bhattacharyya': 0.022235,
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
 'log_samples')

#: Logistic models: P = 1 / (1 + exp(-(intercept + sum coef * feature))).
CONFIDENCE_MODELS = {'refined': {'intercept': -10.936253,
             'coef': {'inliers_ge3': 0.183011,
                      'inliers_ge4': -1.232462,
                      'log_inliers': 1.287528,
                      'inlier_fraction': 9.451509,
                      'mean_iou': 1.737371,
                      'log_s2': -1.33794,
                      'logit_gauss': 0.392944,
                      'margin': -0.265231,
                      'log_samples': -0.155184},
             'metric_offset': {'algebraic': 1.020932,
                               'bbox': -0.009809,
                               'bhattacharyya': -0.222781,
                               'frobenius': 1.025181,
                               'giou': 1.122934,
                               'iou': 1.333697,
                               'qbbox': 0.138632,
                               'wasserstein': 0.128527}},
 'none': {'intercept': -16.11952,
          'coef': {'inliers_ge3': 3.545587,
                   'inliers_ge4': 1.905246,
                   'log_inliers': 3.871776,
                   'inlier_fraction': 0.004988,
                   'mean_iou': 11.03755,
                   'margin': 0.229605,
                   'log_samples': -0.966141}}}
