"""Calibration constants of :mod:`service.localization.confidence` (generated).

Provenance: written by ``python -m bench.trust --fit`` (see that module); the fit uses
only the tuning seeds named in :data:`PROVENANCE`, the bench reports on other seeds.
"""

PROVENANCE = {'command': 'python -m bench.trust --fit', 'tuning_seeds': [100, 102, 101]}

#: k_metric of ``cov = k * max(s^2, f) * (J^T W J)^-1`` (``bench.trust._scale_for``: the
#: smallest and largest mean NEES over the 5 / 10 / 20 cm operating points and the two detector
#: settings of the tuning frames centred on 6).
COVARIANCE_SCALE = {'level_set': 4.077697,
 'algebraic': 3.237079,
 'frobenius': 3.269273,
 'wasserstein': 0.641465,
 'bhattacharyya': 0.502162,
 'bbox': 0.59496,
 'qbbox': 0.771878,
 'iou': 0.475954,
 'giou': 0.467138}

#: f_metric: floor of the a-posteriori variance factor (``bench.trust.S2_FLOOR_QUANTILE`` of
#: the tuning frames' s^2).
S2_FLOOR = {'iou': 0.029444,
 'giou': 0.030112,
 'bbox': 546.522045,
 'qbbox': 386.320362,
 'algebraic': 17713676.513669,
 'frobenius': 20735939.208033,
 'wasserstein': 259.601351,
 'bhattacharyya': 0.021914,
 'level_set': 2.750088}

#: Runner-up / best score (sum of inlier IoUs) at and above which an answer is ambiguous.
AMBIGUITY_RATIO = 0.9

#: The same ratio for a runner-up matching the same map objects (``confidence.is_ambiguous``).
AMBIGUITY_RATIO_SAME_OBJECTS = 0.95

#: Default ``LocalizationOptions.min_confidence``.
MIN_CONFIDENCE = 0.18

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
CONFIDENCE_MODELS = {'refined': {'intercept': -12.30847,
             'coef': {'inliers_ge3': -0.267415,
                      'inliers_ge4': -0.683153,
                      'log_inliers': 1.522423,
                      'inlier_fraction': 10.294868,
                      'mean_iou': 1.216119,
                      'log_s2': -1.207037,
                      'logit_gauss': 0.394416,
                      'margin': -0.117969,
                      'log_samples': -0.019709},
             'metric_offset': {'algebraic': 0.801962,
                               'bbox': 0.052568,
                               'bhattacharyya': -0.29054,
                               'frobenius': 0.771076,
                               'giou': 1.520247,
                               'iou': 1.485833,
                               'qbbox': 0.23828,
                               'wasserstein': 0.299362}},
 'none': {'intercept': -14.047648,
          'coef': {'inliers_ge3': 3.053772,
                   'inliers_ge4': 1.95452,
                   'log_inliers': 2.050158,
                   'inlier_fraction': 0.009025,
                   'mean_iou': 12.360766,
                   'margin': -1.857544,
                   'log_samples': -0.532135}}}
