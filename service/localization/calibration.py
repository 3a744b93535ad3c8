"""Calibration constants of :mod:`service.localization.confidence` (generated).

Provenance: written by ``python -m bench.trust --fit`` (see that module); the fit uses
only the tuning seeds named in :data:`PROVENANCE`, the bench reports on other seeds.
"""

PROVENANCE = {'command': 'placeholder', 'tuning_seeds': []}

#: k_metric of ``cov = k * s^2 * (J^T W J)^-1`` (mean NEES = 6 on the tuning frames: the
#: geometric mean of the mean NEES at the 5 / 10 / 20 cm operating points).
COVARIANCE_SCALE = {'level_set': 16.296504,
 'algebraic': 15.938644,
 'frobenius': 15.120638,
 'wasserstein': 1.662111,
 'bhattacharyya': 1.209316,
 'bbox': 1.403608,
 'qbbox': 1.98629,
 'iou': 1.0,
 'giou': 1.0}

#: Runner-up / best score (sum of inlier IoUs) at and above which an answer is ambiguous.
AMBIGUITY_RATIO = 0.8

#: Default ``LocalizationOptions.min_confidence``.
MIN_CONFIDENCE = 0.0

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
CONFIDENCE_MODELS = {'refined': {'intercept': -8.943671,
             'coef': {'inliers_ge3': 1.107125,
                      'inliers_ge4': -0.606254,
                      'log_inliers': 1.991839,
                      'inlier_fraction': 9.333594,
                      'mean_iou': -8.231579,
                      'min_iou': 5.343406,
                      'log_s2': -0.02531,
                      'logit_gauss': 0.415139,
                      'margin': 0.147515,
                      'log_samples': -0.029021}},
 'none': {'intercept': 37.551392,
          'coef': {'inliers_ge3': 0.0,
                   'inliers_ge4': 0.0,
                   'log_inliers': -3.56261,
                   'inlier_fraction': 0.0,
                   'mean_iou': 0.43674,
                   'min_iou': 1.12791,
                   'margin': 0.77024,
                   'log_samples': -6.995677}}}
