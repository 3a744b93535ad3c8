"""Calibration constants of :mod:`service.localization.confidence` (generated).

Provenance: written by ``python -m bench.trust --fit`` (see that module); the fit uses
only the tuning seeds named in :data:`PROVENANCE`, the bench reports on other seeds.
"""

PROVENANCE = {'command': 'python -m bench.trust --fit --save-data /tmp/tune_s23.json',
 'tuning_seeds': [100, 102, 101]}

#: k_metric of ``cov = k * max(s^2, f) * (J^T W J)^-1`` (``bench.trust._scale_for``: the
#: smallest and largest mean NEES over the 5 / 10 / 20 cm operating points and the two detector
#: settings of the tuning frames centred on 6).
COVARIANCE_SCALE = {'level_set': 2.848987,
 'algebraic': 3.004169,
 'frobenius': 3.054766,
 'wasserstein': 0.457302,
 'bhattacharyya': 0.382505,
 'bbox': 0.449106,
 'qbbox': 0.582003,
 'iou': 0.371627,
 'giou': 0.360375,
 'level_set:unit_weights': 1.172718,
 'algebraic:unit_weights': 0.814815,
 'frobenius:unit_weights': 1.063382,
 'wasserstein:unit_weights': 0.146854,
 'bhattacharyya:unit_weights': 0.165304,
 'bbox:unit_weights': 0.123379,
 'qbbox:unit_weights': 0.252956,
 'iou:unit_weights': 0.201583,
 'giou:unit_weights': 0.191561}

#: f_metric: floor of the a-posteriori variance factor (``bench.trust.S2_FLOOR_QUANTILE`` of
#: the tuning frames' s^2).
S2_FLOOR = {'iou': 0.034848,
 'giou': 0.035534,
 'bbox': 558.366407,
 'qbbox': 412.769714,
 'algebraic': 18480344.70224,
 'frobenius': 21373027.7585,
 'wasserstein': 270.002243,
 'bhattacharyya': 0.022338,
 'level_set': 3.007476,
 'iou:unit_weights': 0.019538,
 'giou:unit_weights': 0.019512,
 'bbox:unit_weights': 602.998511,
 'qbbox:unit_weights': 191.075481,
 'algebraic:unit_weights': 17475293.525193,
 'frobenius:unit_weights': 21115845.041432,
 'wasserstein:unit_weights': 251.448226,
 'bhattacharyya:unit_weights': 0.017589,
 'level_set:unit_weights': 0.862348}

#: Runner-up / best refined chi2 (same detections, same metric) at and below which an answer is
#: ambiguous (``confidence.is_ambiguous``; ``bench.trust.choose_ambiguity_and_threshold``).
AMBIGUITY_CHI2_RATIO = 2.0

#: Runner-up / best score (sum of inlier IoUs) at and above which an answer is ambiguous, when
#: their chi2 do not compare.
AMBIGUITY_RATIO = 0.9

#: The same ratio for a runner-up matching the same map objects (``confidence.is_ambiguous``).
AMBIGUITY_RATIO_SAME_OBJECTS = 0.95

#: Default ``LocalizationOptions.min_confidence`` (with ``AMBIGUITY_CHI2_RATIO``:
#: ``bench.trust.choose_ambiguity_and_threshold``).
MIN_CONFIDENCE = 0.27

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
CONFIDENCE_MODELS = {'refined': {'intercept': -16.145117,
             'coef': {'inliers_ge3': 0.901449,
                      'inliers_ge4': -0.363455,
                      'log_inliers': 0.762358,
                      'inlier_fraction': 9.605591,
                      'mean_iou': 7.77631,
                      'log_s2': -1.276283,
                      'logit_gauss': 0.343983,
                      'margin': -0.500517,
                      'log_samples': -0.211548,
                      'chi2_competitor': 0.05386},
             'metric_offset': {'algebraic': 0.937383,
                               'algebraic:unit_weights': -0.130447,
                               'bbox': 0.060988,
                               'bbox:unit_weights': -0.561474,
                               'bhattacharyya': -0.118535,
                               'bhattacharyya:unit_weights': -0.887453,
                               'frobenius': 0.899901,
                               'frobenius:unit_weights': 0.077726,
                               'giou': 1.029649,
                               'giou:unit_weights': -0.221074,
                               'iou': 1.076699,
                               'iou:unit_weights': -0.112891,
                               'level_set:unit_weights': -0.316439,
                               'qbbox': 0.266238,
                               'qbbox:unit_weights': 0.557414,
                               'wasserstein': 0.272417,
                               'wasserstein:unit_weights': -0.544814}},
 'none': {'intercept': -16.576849,
          'coef': {'inliers_ge3': 3.786856,
                   'inliers_ge4': 1.929234,
                   'log_inliers': 3.833601,
                   'inlier_fraction': 0.003608,
                   'mean_iou': 11.306512,
                   'margin': 0.24305,
                   'log_samples': -0.951828}}}
