"""Calibration constants of :mod:`service.localization.confidence` (generated).

Provenance: written by ``python -m bench.trust --fit`` (see that module); the fit uses
only the tuning seeds named in :data:`PROVENANCE`, the bench reports on other seeds.
"""

PROVENANCE = {'command': 'python -m bench.trust --fit --tune-seeds 100',
 'tuning_seeds': [100, 101]}

#: k_metric of ``cov = k * max(s^2, f) * (J^T W J)^-1`` (the geometric mean of the mean NEES
#: at the 5 and 20 cm operating points = 6 on the tuning frames).
COVARIANCE_SCALE = {'level_set': 6.37024,
 'algebraic': 9.321284,
 'frobenius': 9.20828,
 'wasserstein': 1.185678,
 'bhattacharyya': 0.808934,
 'bbox': 1.092337,
 'qbbox': 1.438357,
 'iou': 0.7332,
 'giou': 0.731347}

#: f_metric: floor of the a-posteriori variance factor (median s^2 of the tuning frames).
S2_FLOOR = {'iou': 0.019277,
 'giou': 0.019462,
 'bbox': 251.030989,
 'qbbox': 168.0113,
 'algebraic': 4596144.574886,
 'frobenius': 5351577.932133,
 'wasserstein': 119.829156,
 'bhattacharyya': 0.013419,
 'level_set': 1.446626}

#: Runner-up / best score (sum of inlier IoUs) at and above which an answer is ambiguous.
AMBIGUITY_RATIO = 0.9

#: The same ratio for a runner-up matching the same map objects (``confidence.is_ambiguous``).
AMBIGUITY_RATIO_SAME_OBJECTS = 0.95

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
CONFIDENCE_MODELS = {'refined': {'intercept': -10.103105,
             'coef': {'inliers_ge3': 0.44362,
                      'inliers_ge4': -0.365015,
                      'log_inliers': 2.995112,
                      'inlier_fraction': 7.795619,
                      'mean_iou': -2.643759,
                      'min_iou': 3.785315,
                      'log_s2': 0.503594,
                      'logit_gauss': 0.430409,
                      'margin': -0.237263,
                      'log_samples': -0.703955},
             'metric_offset': {'algebraic': 0.914615,
                               'bbox': 0.415134,
                               'bhattacharyya': 0.165222,
                               'frobenius': 0.676074,
                               'giou': 1.096554,
                               'iou': 1.197268,
                               'qbbox': 0.504601,
                               'wasserstein': 0.296244}},
 'none': {'intercept': -11.285213,
          'coef': {'inliers_ge3': 1.039887,
                   'inliers_ge4': 3.245157,
                   'log_inliers': -0.040024,
                   'inlier_fraction': 0.060969,
                   'mean_iou': 9.276003,
                   'min_iou': 1.279301,
                   'margin': -1.055971,
                   'log_samples': 0.26382}}}
