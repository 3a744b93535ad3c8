"""Calibration constants of :mod:`service.localization.confidence` (generated).

Provenance: written by ``python -m bench.trust --fit`` (see that module); the fit uses
only the tuning seeds named in :data:`PROVENANCE`, the bench reports on other seeds.
"""

PROVENANCE = {'command': 'python -m bench.trust --fit --save-data /tmp/tune_s22.json',
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
 'iou': 0.366071,
 'giou': 0.355608}

#: f_metric: floor of the a-posteriori variance factor (``bench.trust.S2_FLOOR_QUANTILE`` of
#: the tuning frames' s^2).
S2_FLOOR = {'iou': 0.035787,
 'giou': 0.035789,
 'bbox': 558.366407,
 'qbbox': 412.769714,
 'algebraic': 18480344.70224,
 'frobenius': 21373027.7585,
 'wasserstein': 270.002243,
 'bhattacharyya': 0.022338,
 'level_set': 3.007476}

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
MIN_CONFIDENCE = 0.28

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
CONFIDENCE_MODELS = {'refined': {'intercept': -10.355432,
             'coef': {'inliers_ge3': -0.084652,
                      'inliers_ge4': -1.431211,
                      'log_inliers': 0.646758,
                      'inlier_fraction': 9.995523,
                      'mean_iou': 0.948498,
                      'log_s2': -1.208492,
                      'logit_gauss': 0.420829,
                      'margin': -0.428686,
                      'log_samples': -0.032579,
                      'chi2_competitor': 0.081931},
             'metric_offset': {'algebraic': 1.254916,
                               'bbox': 0.123545,
                               'bhattacharyya': -0.136616,
                               'frobenius': 1.212503,
                               'giou': 1.171925,
                               'iou': 1.174,
                               'qbbox': 0.27956,
                               'wasserstein': 0.257948}},
 'none': {'intercept': -16.576849,
          'coef': {'inliers_ge3': 3.786856,
                   'inliers_ge4': 1.929234,
                   'log_inliers': 3.833601,
                   'inlier_fraction': 0.003608,
                   'mean_iou': 11.306512,
                   'margin': 0.24305,
                   'log_samples': -0.951828}}}
