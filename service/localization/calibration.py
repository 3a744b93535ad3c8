"""Calibration constants of :mod:`service.localization.confidence` (generated).

Provenance: written by ``python -m bench.trust --fit`` (see that module); the fit uses
only the tuning seeds named in :data:`PROVENANCE`, the bench reports on other seeds.
"""

PROVENANCE = {'command': 'python -m bench.trust --fit --tune-seeds 100', 'tuning_seeds': [100]}

#: k_metric of ``cov = k * s^2 * (J^T W J)^-1`` (mean NEES = 6 on the tuning frames: the
#: geometric mean of the mean NEES at the 5 / 10 / 20 cm operating points).
COVARIANCE_SCALE = {'level_set': 9.882225,
 'algebraic': 13.961773,
 'frobenius': 13.696223,
 'wasserstein': 1.516563,
 'bhattacharyya': 1.04299,
 'bbox': 1.395759,
 'qbbox': 2.437384,
 'iou': 0.007598,
 'giou': 0.007454}

#: Runner-up / best score (sum of inlier IoUs) at and above which an answer is ambiguous.
AMBIGUITY_RATIO = 0.8

#: Default ``LocalizationOptions.min_confidence``.
MIN_CONFIDENCE = 0.14

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
CONFIDENCE_MODELS = {'refined': {'intercept': -13.37851,
             'coef': {'inliers_ge3': 0.806596,
                      'inliers_ge4': 0.252633,
                      'log_inliers': 4.005983,
                      'inlier_fraction': 3.976124,
                      'mean_iou': 4.845304,
                      'min_iou': 2.158172,
                      'log_s2': 0.003539,
                      'logit_gauss': 0.267048,
                      'margin': -0.540692,
                      'log_samples': -0.502742}},
 'none': {'intercept': -6.203164,
          'coef': {'inliers_ge3': 2.214148,
                   'inliers_ge4': 1.112694,
                   'log_inliers': 0.947283,
                   'inlier_fraction': 0.245141,
                   'mean_iou': 7.546036,
                   'min_iou': -2.400631,
                   'margin': -4.210391,
                   'log_samples': -0.16295}}}
