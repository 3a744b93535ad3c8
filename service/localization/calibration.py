"""Calibration constants of :mod:`quadloc.service.localization.confidence` (generated).

Provenance: written by ``python -m bench.trust --fit`` (see that module); the fit uses
only the tuning seeds named in :data:`PROVENANCE`, the bench reports on other seeds.
"""

PROVENANCE = {'command': 'python -m bench.trust --fit --load-data /tmp/fit/tune_s24g.json',
 'tuning_seeds': [100, 102, 104, 106, 101, 103]}

#: k_metric of ``cov = k * max(s^2, f) * (J^T W J)^-1`` (``bench.trust._scale_for``: the
#: smallest and largest mean NEES over the 5 / 10 / 20 cm operating points and the two detector
#: settings of the tuning frames centred on 6).
COVARIANCE_SCALE = {'level_set': 3.061898,
 'algebraic': 3.772087,
 'frobenius': 3.641786,
 'wasserstein': 0.539845,
 'bhattacharyya': 0.402706,
 'bbox': 0.51237,
 'qbbox': 0.588988,
 'iou': 0.380141,
 'giou': 0.371557,
 'level_set:unit_weights': 1.165608,
 'algebraic:unit_weights': 0.864225,
 'frobenius:unit_weights': 1.182148,
 'wasserstein:unit_weights': 0.161372,
 'bhattacharyya:unit_weights': 0.179969,
 'bbox:unit_weights': 0.126336,
 'qbbox:unit_weights': 0.272271,
 'iou:unit_weights': 0.210558,
 'giou:unit_weights': 0.188999}

#: f_metric: floor of the a-posteriori variance factor (``bench.trust.S2_FLOOR_QUANTILE`` of
#: the tuning frames' s^2).
S2_FLOOR = {'iou': 0.034884,
 'giou': 0.035479,
 'bbox': 560.215493,
 'qbbox': 440.700189,
 'algebraic': 18179371.466708,
 'frobenius': 21470708.534082,
 'wasserstein': 264.620932,
 'bhattacharyya': 0.022377,
 'level_set': 2.965208,
 'iou:unit_weights': 0.019562,
 'giou:unit_weights': 0.019785,
 'bbox:unit_weights': 588.273726,
 'qbbox:unit_weights': 169.404794,
 'algebraic:unit_weights': 18008479.993014,
 'frobenius:unit_weights': 21300239.347138,
 'wasserstein:unit_weights': 251.513019,
 'bhattacharyya:unit_weights': 0.016278,
 'level_set:unit_weights': 0.810406}

#: Runner-up / best refined chi2 (same detections, same metric) at and below which an answer is
#: ambiguous (``confidence.is_ambiguous``; ``bench.trust.choose_ambiguity_and_threshold``).
AMBIGUITY_CHI2_RATIO = 1.25

#: Runner-up / best score (sum of inlier IoUs) at and above which an answer is ambiguous, when
#: their chi2 do not compare.
AMBIGUITY_RATIO = 0.9

#: The same ratio for a runner-up matching the same map objects (``confidence.is_ambiguous``).
AMBIGUITY_RATIO_SAME_OBJECTS = 0.95

#: Default ``LocalizationOptions.min_confidence`` (with ``AMBIGUITY_CHI2_RATIO``:
#: ``bench.trust.choose_ambiguity_and_threshold``).
MIN_CONFIDENCE = 0.36

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
 'chi2_competitor',
 'gravity')

#: Logistic models: P = 1 / (1 + exp(-(intercept + sum coef * feature))).
CONFIDENCE_MODELS = {'refined': {'intercept': -14.159317,
             'coef': {'inliers_ge3': 1.013804,
                      'inliers_ge4': -0.175857,
                      'log_inliers': 0.47283,
                      'inlier_fraction': 7.287873,
                      'mean_iou': 7.631693,
                      'log_s2': -0.610058,
                      'logit_gauss': 0.351359,
                      'margin': 0.016793,
                      'log_samples': -0.101654,
                      'chi2_competitor': 0.1227,
                      'gravity': -0.386246},
             'metric_offset': {'algebraic': 1.046997,
                               'algebraic:unit_weights': -0.356343,
                               'bbox': 0.079216,
                               'bbox:unit_weights': -0.679211,
                               'bhattacharyya': -0.170347,
                               'bhattacharyya:unit_weights': -0.999875,
                               'frobenius': 0.931686,
                               'frobenius:unit_weights': -0.173938,
                               'giou': 0.831191,
                               'giou:unit_weights': -0.304363,
                               'iou': 0.88218,
                               'iou:unit_weights': -0.198186,
                               'level_set:unit_weights': -0.337894,
                               'qbbox': 0.388617,
                               'qbbox:unit_weights': 0.345234,
                               'wasserstein': 0.125206,
                               'wasserstein:unit_weights': -0.602988}},
 'none': {'intercept': -15.733101,
          'coef': {'inliers_ge3': 3.911833,
                   'inliers_ge4': 1.845376,
                   'log_inliers': 4.36391,
                   'inlier_fraction': -2.404452,
                   'mean_iou': 12.736385,
                   'margin': -0.004131,
                   'log_samples': -1.021954,
                   'gravity': 0.0}}}
