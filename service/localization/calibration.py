"""Calibration constants of :mod:`service.localization.confidence` (generated).

Provenance: written by ``python -m bench.trust --fit`` (see that module); the fit uses
only the tuning seeds named in :data:`PROVENANCE`, the bench reports on other seeds.
"""

PROVENANCE = {'command': 'python -m bench.trust --fit --tune-seeds 100', 'tuning_seeds': [100]}

#: k_metric of ``cov = k * max(s^2, f) * (J^T W J)^-1`` (the geometric mean of the mean NEES
#: at the 5 and 20 cm operating points = 6 on the tuning frames).
COVARIANCE_SCALE = {'level_set': 6.553717,
 'algebraic': 9.611507,
 'frobenius': 9.139516,
 'wasserstein': 1.188119,
 'bhattacharyya': 0.834467,
 'bbox': 1.102262,
 'qbbox': 1.534207,
 'iou': 0.002381,
 'giou': 0.002272}

#: f_metric: floor of the a-posteriori variance factor (median s^2 of the tuning frames).
S2_FLOOR = {'iou': 34.983962,
 'giou': 34.960848,
 'bbox': 251.030989,
 'qbbox': 159.390606,
 'algebraic': 4382789.957662,
 'frobenius': 5602330.785658,
 'wasserstein': 124.586562,
 'bhattacharyya': 0.013929,
 'level_set': 1.39548}

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
CONFIDENCE_MODELS = {'refined': {'intercept': -11.283059,
             'coef': {'inliers_ge3': 0.618578,
                      'inliers_ge4': 0.045584,
                      'log_inliers': 3.536275,
                      'inlier_fraction': 5.367522,
                      'mean_iou': 1.788793,
                      'min_iou': 2.435986,
                      'log_s2': 0.02125,
                      'logit_gauss': 0.315568,
                      'margin': -0.403144,
                      'log_samples': -0.620367}},
 'none': {'intercept': -6.203164,
          'coef': {'inliers_ge3': 2.214148,
                   'inliers_ge4': 1.112694,
                   'log_inliers': 0.947283,
                   'inlier_fraction': 0.245141,
                   'mean_iou': 7.546036,
                   'min_iou': -2.400631,
                   'margin': -4.210391,
                   'log_samples': -0.16295}}}
