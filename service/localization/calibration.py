"""Calibration constants of :mod:`service.localization.confidence` (generated).

Provenance: written by ``python -m bench.trust --fit`` (see that module); the fit uses
only the tuning seeds named in :data:`PROVENANCE`, the bench reports on other seeds.
"""

PROVENANCE = {'command': 'python -m bench.trust --fit --save-data /tmp/i12/tune2.json',
 'tuning_seeds': [100, 102, 101]}

#: k_metric of ``cov = k * max(s^2, f) * (J^T W J)^-1`` (``bench.trust._scale_for``: the
#: smallest and largest mean NEES over the 5 / 10 / 20 cm operating points and the two detector
#: settings of the tuning frames centred on 6).
COVARIANCE_SCALE = {'level_set': 2.848089,
 'algebraic': 3.058089,
 'frobenius': 3.025348,
 'wasserstein': 0.457819,
 'bhattacharyya': 0.386441,
 'bbox': 0.447184,
 'qbbox': 0.578376,
 'iou': 0.435593,
 'giou': 0.433231}

#: f_metric: floor of the a-posteriori variance factor (``bench.trust.S2_FLOOR_QUANTILE`` of
#: the tuning frames' s^2).
S2_FLOOR = {'iou': 0.028949,
 'giou': 0.029401,
 'bbox': 557.708739,
 'qbbox': 409.402733,
 'algebraic': 18052346.834494,
 'frobenius': 21528570.091641,
 'wasserstein': 269.81267,
 'bhattacharyya': 0.022029,
 'level_set': 3.010206}

#: Runner-up / best score (sum of inlier IoUs) at and above which an answer is ambiguous.
AMBIGUITY_RATIO = 0.9

#: The same ratio for a runner-up matching the same map objects (``confidence.is_ambiguous``).
AMBIGUITY_RATIO_SAME_OBJECTS = 0.95

#: Default ``LocalizationOptions.min_confidence``.
MIN_CONFIDENCE = 0.21

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
CONFIDENCE_MODELS = {'refined': {'intercept': -12.113509,
             'coef': {'inliers_ge3': 0.131051,
                      'inliers_ge4': -1.246913,
                      'log_inliers': 1.548832,
                      'inlier_fraction': 10.639834,
                      'mean_iou': 1.474241,
                      'log_s2': -0.982249,
                      'logit_gauss': 0.396646,
                      'margin': -0.03977,
                      'log_samples': -0.217721},
             'metric_offset': {'algebraic': 0.999418,
                               'bbox': -0.006818,
                               'bhattacharyya': -0.209461,
                               'frobenius': 0.99872,
                               'giou': 1.461059,
                               'iou': 1.444145,
                               'qbbox': 0.13409,
                               'wasserstein': 0.137442}},
 'none': {'intercept': -14.639233,
          'coef': {'inliers_ge3': 3.654261,
                   'inliers_ge4': 2.042006,
                   'log_inliers': 2.045277,
                   'inlier_fraction': 0.013314,
                   'mean_iou': 12.370887,
                   'margin': -2.001905,
                   'log_samples': -0.508047}}}
