"""Calibration constants of :mod:`service.localization.confidence` (generated).

Provenance: written by ``python -m bench.trust --fit`` (see that module); the fit uses
only the tuning seeds named in :data:`PROVENANCE`, the bench reports on other seeds.
"""

PROVENANCE = {'command': 'python -m bench.trust --fit', 'tuning_seeds': [100, 101]}

#: k_metric of ``cov = k * max(s^2, f) * (J^T W J)^-1`` (the geometric mean of the mean NEES
#: at the 5 and 20 cm operating points = 6 on the tuning frames).
COVARIANCE_SCALE = {'level_set': 6.37021,
 'algebraic': 9.280019,
 'frobenius': 9.101989,
 'wasserstein': 1.185679,
 'bhattacharyya': 0.808933,
 'bbox': 1.092336,
 'qbbox': 1.44088,
 'iou': 0.013084,
 'giou': 0.013523}

#: f_metric: floor of the a-posteriori variance factor (median s^2 of the tuning frames).
S2_FLOOR = {'iou': 21.206645,
 'giou': 21.253349,
 'bbox': 251.030989,
 'qbbox': 168.0113,
 'algebraic': 4635797.269015,
 'frobenius': 5476954.358774,
 'wasserstein': 119.829156,
 'bhattacharyya': 0.013419,
 'level_set': 1.446626}

#: Runner-up / best score (sum of inlier IoUs) at and above which an answer is ambiguous.
AMBIGUITY_RATIO = 0.8

#: Default ``LocalizationOptions.min_confidence``.
MIN_CONFIDENCE = 0.15

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
CONFIDENCE_MODELS = {'refined': {'intercept': -13.510085,
             'coef': {'inliers_ge3': 0.520809,
                      'inliers_ge4': -0.165326,
                      'log_inliers': 3.597462,
                      'inlier_fraction': 6.783252,
                      'mean_iou': 2.481203,
                      'min_iou': 2.420872,
                      'log_s2': 0.453324,
                      'logit_gauss': 0.304448,
                      'margin': -0.46548,
                      'log_samples': -0.515702},
             'metric_offset': {'algebraic': 0.386239,
                               'bbox': 0.162951,
                               'bhattacharyya': 0.024713,
                               'frobenius': 0.174707,
                               'giou': 0.796752,
                               'iou': 0.794928,
                               'qbbox': 0.307062,
                               'wasserstein': 0.080119}},
 'none': {'intercept': -5.782306,
          'coef': {'inliers_ge3': 2.185712,
                   'inliers_ge4': 1.571655,
                   'log_inliers': 0.290337,
                   'inlier_fraction': 0.282513,
                   'mean_iou': 6.528097,
                   'min_iou': -2.086739,
                   'margin': -3.779695,
                   'log_samples': 0.043186}}}
