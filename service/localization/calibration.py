"""Calibration constants of :mod:`service.localization.confidence` (generated).

Provenance: written by ``python -m bench.trust --fit`` (see that module); the fit uses
only the tuning seeds named in :data:`PROVENANCE`, the bench reports on other seeds.
"""

PROVENANCE = {'command': 'python -m bench.trust --fit --tune-seeds 100 --tune-noisy-seed 101',
 'tuning_seeds': [100, 101]}

#: k_metric of ``cov = k * max(s^2, f) * (J^T W J)^-1`` (the geometric mean of the mean NEES
#: at the 5 and 20 cm operating points = 6 on the tuning frames).
COVARIANCE_SCALE = {'level_set': 6.350211,
 'algebraic': 9.031034,
 'frobenius': 8.909532,
 'wasserstein': 1.163404,
 'bhattacharyya': 0.800246,
 'bbox': 1.070288,
 'qbbox': 1.411267,
 'iou': 0.013063,
 'giou': 0.013491}

#: f_metric: floor of the a-posteriori variance factor (median s^2 of the tuning frames).
S2_FLOOR = {'iou': 21.429994,
 'giou': 21.58263,
 'bbox': 252.762249,
 'qbbox': 170.687896,
 'algebraic': 4810766.113537,
 'frobenius': 5622030.383866,
 'wasserstein': 121.609413,
 'bhattacharyya': 0.01369,
 'level_set': 1.446626}

#: Runner-up / best score (sum of inlier IoUs) at and above which an answer is ambiguous.
AMBIGUITY_RATIO = 0.8

#: Default ``LocalizationOptions.min_confidence``.
MIN_CONFIDENCE = 0.13

#: Features of the confidence model (``confidence.evidence_features``), in order.
CONFIDENCE_FEATURES = ('inliers_ge3',
 'inliers_ge4',
 'log_inliers',
 'inlier_fraction',
 'mean_iou',
 'min_iou',
 'log_s2',
 'logit_gauss',
 'margin',
 'log_samples')

#: Logistic models: P = 1 / (1 + exp(-(intercept + sum coef * feature))).
CONFIDENCE_MODELS = {'refined': {'intercept': -13.554753,
             'coef': {'inliers_ge3': 0.284135,
                      'inliers_ge4': -0.306847,
                      'log_inliers': 4.124545,
                      'inlier_fraction': 6.679045,
                      'mean_iou': 2.194006,
                      'min_iou': 2.515788,
                      'log_s2': 0.158784,
                      'logit_gauss': 0.315358,
                      'margin': -0.037183,
                      'log_samples': -0.56824},
             'metric_offset': {'algebraic': -2.090823,
                               'bbox': -0.708961,
                               'bhattacharyya': 0.635215,
                               'frobenius': -2.334938,
                               'giou': 0.762348,
                               'iou': 0.760997,
                               'qbbox': -0.591364,
                               'wasserstein': -0.662494}},
 'none': {'intercept': -5.869284,
          'coef': {'inliers_ge3': 2.275426,
                   'inliers_ge4': 1.743203,
                   'log_inliers': 1.322622,
                   'inlier_fraction': 0.242863,
                   'mean_iou': 6.345171,
                   'min_iou': -2.281494,
                   'margin': -3.616093,
                   'log_samples': -0.385484}}}
