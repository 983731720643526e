"""Line confidence: evidence, the calibrated model, unclear lines and what the answer says."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np

from darkread.cloud.confidence import (
    FEATURES,
    ConfidenceModel,
    LineRead,
    PageConditions,
    judge,
    judge_lines,
    line_evidence,
    load_model,
    spoken_answer,
)


def model(threshold: float = 0.5) -> ConfidenceModel:
    """Confidence from the recogniser's weakest character alone: sure at 1, unsure below 0.5."""
    weights = tuple(8.0 if name == "ocr_min" else 0.0 for name in FEATURES)
    means = tuple(0.5 if name == "ocr_min" else 0.0 for name in FEATURES)
    return ConfidenceModel(FEATURES, means, (1.0,) * len(FEATURES), weights, 0.0, threshold,
                           dark_ink_solid=0.2, fast_head_speed=math.log1p(200.0), small_height_px=9.0)


def model_json_text() -> str:
    m = model()
    return json.dumps({"features": list(m.features), "mean": list(m.mean), "scale": list(m.scale), "weights": list(m.weights),
                       "intercept": m.intercept, "answer_threshold": m.answer_threshold, "dark_ink_solid": m.dark_ink_solid,
                       "fast_head_speed": m.fast_head_speed, "small_height_px": m.small_height_px})


def page() -> np.ndarray:
    grey = np.full((40, 100), 255, np.uint8)
    grey[10:20, 10:60] = 0  # solid ink
    grey[25:35, 10:60] = 160  # ink the frames disagreed on
    return grey


def test_evidence_describes_the_line_and_the_page() -> None:
    views = np.full((40, 100), 6, np.int32)
    evidence = line_evidence(page(), (0, 8, 100, 22), "the fox", "tho fox", (0.9, 0.5, 0.99), known_share=1.0,
                             views=views, conditions=PageConditions(frame_rate_hz=20.0, head_speed_px_s=50.0))
    assert evidence["ocr_min"] == 0.5 and evidence["ocr_low_share"] == 1 / 3
    assert evidence["height_px"] == 14 and evidence["ink_solid"] == 1.0
    assert evidence["corrected_share"] == 0.5 and evidence["log_views"] == math.log1p(6)
    assert evidence["log_frame_rate"] == math.log(20.0) and evidence["log_head_speed"] == math.log1p(50.0)
    grey_line = line_evidence(page(), (0, 23, 100, 37), "x", "x", (0.9,), known_share=1.0)
    assert grey_line["ink_solid"] == 0.0 and "log_views" not in grey_line and "log_frame_rate" not in grey_line
    assert "edge_shed" not in evidence  # the page did not say
    starved = line_evidence(page(), (0, 8, 100, 22), "the fox", "the fox", (0.9,), known_share=1.0,
                            conditions=PageConditions(frame_rate_hz=5.0, head_speed_px_s=50.0, shed_level=2.5))
    assert starved["edge_shed"] == 2.5 and "edge_shed" not in grey_line  # unknown (a glasses page): not evidence
    dim = line_evidence(page(), (0, 8, 100, 22), "the fox", "the fox", (0.9,), known_share=1.0,
                        conditions=PageConditions(light_lux=6.0))
    assert dim["log_lux"] == math.log(6.0) and "log_lux" not in evidence  # the glasses did not say: not evidence


def test_the_measured_light_decides_whether_more_light_would_help() -> None:
    """Where the glasses measured the light and the model knows what dim measures as, "more light" is
    said for a dim page only, and also while the head moves (both would help); where they did not,
    or the model saw no measured light, the frames' agreement stands in for it."""
    knows = dataclasses.replace(model(), dim_lux=8.0)
    dim_and_still = judge({"ocr_min": 0.2, "ink_solid": 0.9, "log_lux": math.log(5.0), "log_head_speed": math.log1p(20.0)}, knows)
    assert dim_and_still.reasons == ("too_dark",)  # solid ink, yet measured dim
    dim_and_moving = judge({"ocr_min": 0.2, "log_lux": math.log(5.0), "log_head_speed": math.log1p(400.0)}, knows)
    assert dim_and_moving.reasons == ("too_dark", "too_much_motion")
    lit = judge({"ocr_min": 0.2, "ink_solid": 0.1, "log_lux": math.log(200.0), "log_head_speed": math.log1p(20.0)}, knows)
    assert lit.reasons == ("look_again",)  # grey ink on a lit page: light is not what is missing
    assert judge({"ocr_min": 0.2, "log_lux": math.log(9.0)}, knows).reasons == ("look_again",)  # above the dim light
    assert spoken_answer([("x", dim_and_moving), ("y", dim_and_moving)]) == (
        "The whole page is unclear.\nPlease add more light.\nPlease stop moving.")
    unknowing = judge({"ocr_min": 0.2, "ink_solid": 0.1, "log_lux": math.log(200.0), "log_head_speed": math.log1p(20.0)}, model())
    assert unknowing.reasons == ("too_dark",)  # a model fitted on no measured light: the frames' agreement decides
    assert ConfidenceModel.from_json({**json.loads(model_json_text()), "dim_lux": 8.0}).dim_lux == 8.0


def test_unsure_lines_are_unclear_with_what_would_help() -> None:
    sure = judge({"ocr_min": 0.95, "log_frame_rate": math.log(30.0)}, model())
    assert sure.status == "read" and sure.confidence > 0.9 and sure.reasons == ()
    dark = judge({"ocr_min": 0.2, "ink_solid": 0.1, "log_head_speed": math.log1p(20.0)}, model())
    assert dark.status == "unclear" and dark.reasons == ("too_dark",)
    shaky = judge({"ocr_min": 0.2, "ink_solid": 0.1, "log_head_speed": math.log1p(400.0)}, model())
    assert shaky.reasons == ("too_much_motion",)  # frames that disagree while the head moves fast: motion first
    small = judge({"ocr_min": 0.2, "height_px": 7.0}, model())
    assert small.reasons == ("too_small",)
    assert judge({"ocr_min": 0.2}, model()).reasons == ("look_again",)
    busy = judge({"ocr_min": 0.2, "edge_shed": 3.0}, model())
    assert busy.reasons == ("glasses_busy",)  # the glasses shed work: that, not the reader, is what to fix first
    assert judge({"ocr_min": 0.2, "edge_shed": 1.0}, model()).reasons == ("look_again",)  # its dithered pair kept: not the cause
    assert spoken_answer([("x", busy)]) == "One line unclear.\nThe glasses could not keep up. Look at that line again."


def test_lines_without_character_scores_are_answered_unjudged() -> None:
    lines = [LineRead("sure", "sure", (0, 8, 100, 22), (0.99, 0.98)), LineRead("remote", "remote", None, None)]
    judged = judge_lines(lines, page(), model())
    assert judged[0] is not None and judged[0].status == "read" and judged[1] is None


def test_the_spoken_answer_reads_the_sure_lines_and_says_what_would_help() -> None:
    read = judge({"ocr_min": 0.95}, model())
    shaky = judge({"ocr_min": 0.1, "log_head_speed": math.log1p(500.0)}, model())
    said = spoken_answer([("the quick fox", read), ("xq", shaky), ("zz", shaky), ("jumps", read)])
    assert said == "the quick fox\nTwo lines unclear.\njumps\nPlease stop moving."  # half the page unclear: the guidance
    assert spoken_answer([("a", read), ("b", read), ("c", shaky)]) == "a\nb\nOne line unclear."
    assert spoken_answer([("guess", shaky)]) == "One line unclear.\nPlease stop moving."


def test_the_shipped_model_loads() -> None:
    shipped = load_model()
    assert shipped.features == FEATURES and 0.0 <= shipped.answer_threshold < 1.0
    assert 0.0 <= shipped.probability({}) <= 1.0


def test_a_band_of_ink_read_as_nothing_is_an_unclear_line() -> None:
    judged = judge_lines([LineRead("", "", (0, 23, 100, 37), None)], page(), model(),
                         conditions=PageConditions(frame_rate_hz=10.0, head_speed_px_s=900.0))
    assert judged[0] is not None and judged[0].status == "unclear" and judged[0].confidence == 0.0
    assert judged[0].reasons == ("too_much_motion",)
    assert spoken_answer([("", judged[0])] * 3) == "The whole page is unclear.\nPlease stop moving."  # (no count of smeared bands)
