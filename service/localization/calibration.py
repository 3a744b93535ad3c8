"""Calibration constants of :mod:`quadloc.service.localization.confidence`
(generated: do not edit).

Fitted (:mod:`quadloc.service.localization.calibration_fit`) from the solve records
``bench/data/calibration_records.json.gz`` by::

    python -m quadloc.service.localization.calibration_fit bench/data/calibration_records.json.gz bench/data/building_calibration_records.json.gz

The records were made by ``python -m bench.trust --fit`` at commit ebaffa4;
tuning seeds only (:data:`PROVENANCE`): ``bench.trust`` reports on other seeds.

With ``bench/data/building_calibration_records.json.gz``, made by ``python -m bench.building --calibration-records bench/data/building_calibration_records.json.gz --frames 40`` at commit 262ca33 (tuning seeds [5, 7, 9, 11, 13, 15, 17, 19, 21, 23, 25, 27, 29, 31, 33, 35]; ``bench.building`` reports on other seeds).
"""
# ruff: noqa: E501  (generated: the commands and sha256 sums are not wrapped)

PROVENANCE = {'records': 'bench/data/calibration_records.json.gz',
 'records_sha256': 'b9a24248d80e0c5eb2b51ca7b2b4d2bf134aaa413246768bcad4cb071a420509',
 'command': 'python -m quadloc.service.localization.calibration_fit '
            'bench/data/calibration_records.json.gz '
            'bench/data/building_calibration_records.json.gz',
 'records_command': 'python -m bench.trust --fit',
 'records_commit': 'ebaffa4',
 'tuning_seeds': [100, 102, 104, 106, 101, 103],
 'extra_records': [{'records': 'bench/data/building_calibration_records.json.gz',
                    'records_sha256': '7e49e8ca15ca340fa549eda272debcf02812d267694d908bd017168b138d96ac',
                    'records_command': 'python -m bench.building --calibration-records '
                                       'bench/data/building_calibration_records.json.gz '
                                       '--frames 40',
                    'records_commit': '262ca33',
                    'tuning_seeds': [5,
                                     7,
                                     9,
                                     11,
                                     13,
                                     15,
                                     17,
                                     19,
                                     21,
                                     23,
                                     25,
                                     27,
                                     29,
                                     31,
                                     33,
                                     35]}]}

#: k_key of ``cov = k * max(s^2, f) * t(n) * (J^T W J)^-1`` (``calibration_fit.
#: fit_covariance_scale``: the smallest and largest mean NEES over the 5 / 10 / 20 cm operating
#: points and the recording groups of the tuning frames centred on 6).
COVARIANCE_SCALE = {'level_set': 3.056535,
 'algebraic': 3.762694,
 'frobenius': 3.638759,
 'wasserstein': 0.539851,
 'bhattacharyya': 0.402522,
 'bbox': 0.516082,
 'qbbox': 0.590112,
 'iou': 0.380251,
 'giou': 0.370804,
 'level_set:unit_weights': 1.178971,
 'algebraic:unit_weights': 0.868042,
 'frobenius:unit_weights': 1.181556,
 'wasserstein:unit_weights': 0.161266,
 'bhattacharyya:unit_weights': 0.183366,
 'bbox:unit_weights': 0.1242,
 'qbbox:unit_weights': 0.287245,
 'iou:unit_weights': 0.216096,
 'giou:unit_weights': 0.1916}

#: f_key: floor of the a-posteriori variance factor (``calibration_fit.fit_s2_floor``: the 0.9
#: quantile of the tuning frames' s^2).
S2_FLOOR = {'iou': 0.034885,
 'giou': 0.035566,
 'bbox': 559.033293,
 'qbbox': 441.087089,
 'algebraic': 18228013.270774,
 'frobenius': 21489781.131601,
 'wasserstein': 265.311808,
 'bhattacharyya': 0.022389,
 'level_set': 2.971194,
 'iou:unit_weights': 0.019006,
 'giou:unit_weights': 0.019488,
 'bbox:unit_weights': 587.514688,
 'qbbox:unit_weights': 159.978022,
 'algebraic:unit_weights': 18052796.337624,
 'frobenius:unit_weights': 21316484.775149,
 'wasserstein:unit_weights': 251.716141,
 'bhattacharyya:unit_weights': 0.015934,
 'level_set:unit_weights': 0.803039}

#: Runner-up / best refined chi2 (same detections, same metric) at and below which an answer is
#: ambiguous (``confidence.is_ambiguous``; ``calibration_fit.choose_ambiguity_and_threshold``).
AMBIGUITY_CHI2_RATIO = 1.25

#: Runner-up / best score (sum of inlier IoUs) at and above which an answer is ambiguous, when
#: their chi2 do not compare.
AMBIGUITY_RATIO = 0.9

#: The same ratio for a runner-up matching the same map objects (``confidence.is_ambiguous``).
AMBIGUITY_RATIO_SAME_OBJECTS = 0.95

#: Default ``LocalizationOptions.min_confidence`` (with ``AMBIGUITY_CHI2_RATIO``:
#: ``calibration_fit.choose_ambiguity_and_threshold``).
MIN_CONFIDENCE = 0.36

#: The same default for the answers of a place search (a large map), chosen on the building
#: frames' decision sets at that ratio (``calibration_fit.choose_place_threshold``).
MIN_CONFIDENCE_PLACES = 0.5

#: The ambiguity chi2 ratio of a place-search answer held by a minimal sample of inliers
#: (``confidence.answer_chi2_ratio``), chosen with ``MIN_CONFIDENCE_PLACES``.
AMBIGUITY_CHI2_RATIO_MINIMAL_PLACES = 3.0

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

#: Logistic models: P = 1 / (1 + exp(-(intercept + metric_offset + sum coef * feature))); an
#: answer of the place search: P = 1 / (1 + exp(-(places intercept + coef * z))), z the refined
#: model's log-odds (``confidence.confidence_logit``).
CONFIDENCE_MODELS = {'refined': {'intercept': -14.033732,
             'coef': {'inliers_ge3': 1.017204,
                      'inliers_ge4': -0.163843,
                      'log_inliers': 0.471651,
                      'inlier_fraction': 7.27819,
                      'mean_iou': 7.584767,
                      'log_s2': -0.625262,
                      'logit_gauss': 0.351904,
                      'margin': 0.013686,
                      'log_samples': -0.10571,
                      'chi2_competitor': 0.107625,
                      'gravity': -0.390908},
             'metric_offset': {'algebraic': 1.038311,
                               'algebraic:unit_weights': -0.355195,
                               'bbox': 0.074257,
                               'bbox:unit_weights': -0.710213,
                               'bhattacharyya': -0.183562,
                               'bhattacharyya:unit_weights': -1.012036,
                               'frobenius': 0.920884,
                               'frobenius:unit_weights': -0.184604,
                               'giou': 0.799599,
                               'giou:unit_weights': -0.314018,
                               'iou': 0.851299,
                               'iou:unit_weights': -0.207883,
                               'level_set:unit_weights': -0.336453,
                               'qbbox': 0.381381,
                               'qbbox:unit_weights': 0.341397,
                               'wasserstein': 0.115265,
                               'wasserstein:unit_weights': -0.616519}},
 'none': {'intercept': -15.733101,
          'coef': {'inliers_ge3': 3.911833,
                   'inliers_ge4': 1.845376,
                   'log_inliers': 4.36391,
                   'inlier_fraction': -2.404452,
                   'mean_iou': 12.736385,
                   'margin': -0.004131,
                   'log_samples': -1.021954,
                   'gravity': 0.0}},
 'places': {'intercept': 1.333902, 'coef': {'refined_logit': 0.961724}}}
