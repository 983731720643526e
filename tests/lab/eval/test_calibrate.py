"""Fitting and measuring the line-confidence model; selective reading figures."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from darkread.cloud.confidence import ConfidenceModel
from darkread.lab.eval.calibrate import calibrate, check, fit_logistic, light_limit, split
from darkread.lab.eval.selective import LineOutcome, match_lines, reliability, risk_coverage, selective


def synthetic_lines(n: int = 600, seed: int = 3) -> list[LineOutcome]:
    """Lines whose chance of being right is a known logistic function of one piece of evidence."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        ocr_min = float(rng.uniform(0, 1))
        right = rng.random() < 1 / (1 + np.exp(-(10 * ocr_min - 5)))
        lux = float(rng.choice([5, 30]))
        out.append(LineOutcome(f"{i:03d}_x", lux, "walking" if i % 3 == 0 else "still", "words", 0.0 if right else 0.3, 28,
                               {"ocr_min": ocr_min, "ink_solid": 0.1 if lux == 5 else 0.3,
                                "log_head_speed": 5.0 if i % 3 == 0 else 2.0}))
    return out


def test_logistic_fit_recovers_a_known_slope() -> None:
    rng = np.random.default_rng(0)
    x = rng.normal(size=(4000, 1))
    y = (rng.random(4000) < 1 / (1 + np.exp(-(2.0 * x[:, 0] + 0.5)))).astype(float)
    w, b = fit_logistic(x, y, ridge=0.0)
    assert abs(w[0] - 2.0) < 0.2 and abs(b - 0.5) < 0.15


def test_ece_is_zero_when_confidence_matches_the_outcomes() -> None:
    p = np.array([0.25] * 4 + [0.75] * 4)
    right = np.array([1, 0, 0, 0, 1, 1, 1, 0], dtype=float)
    ece, rows = reliability(p, right)
    assert ece == 0.0 and [n for *_, n in rows] == [4, 4]
    assert reliability(np.array([0.9, 0.9]), np.array([0.0, 0.0]))[0] == 0.9


def test_calibrate_writes_a_model_that_is_calibrated_on_held_out_lines(tmp_path: Path) -> None:
    lines = synthetic_lines()
    fitting, held = split(lines)
    assert {int(ln.recording[:3]) // 4 % 2 for ln in held} == {1} and len(fitting) + len(held) == len(lines)
    model, ece = calibrate(lines, tmp_path / "model.json", tmp_path / "report", target_risk=0.05)
    assert ece < 0.08
    shipped = ConfidenceModel.from_json(json.loads((tmp_path / "model.json").read_text()))
    assert shipped.answer_threshold == model.answer_threshold > 0
    assert 0.1 < shipped.dark_ink_solid < 0.3 and 2.0 < shipped.fast_head_speed < 5.0
    assert (tmp_path / "report" / "reliability.png").stat().st_size > 0
    assert "Held-out ECE" in (tmp_path / "report" / "calibration.md").read_text()
    answered = selective(held, shipped)
    everything = selective(held, shipped.__class__(**{**shipped.__dict__, "answer_threshold": 0.0}))
    assert answered.cer_answered is not None and everything.cer_all is not None
    assert answered.cer_answered < everything.cer_all and 0 < answered.coverage < 1 and everything.coverage == 1
    coverage, risk = risk_coverage(held, shipped)
    assert coverage[-1] == 1.0 and risk[0] <= risk[-1]


def test_the_light_that_counts_as_dim_is_fitted_where_the_glasses_measured_it(tmp_path: Path) -> None:
    """Halfway (log lux) between the dim pages' measured light and the lit ones', no higher than the
    dimmest tenth of the lit lines; no limit (and none in the JSON) from lines without a measurement."""
    lines = synthetic_lines()
    assert light_limit(lines) is None
    measured = [dataclasses.replace(ln, evidence={**ln.evidence, "log_lux": np.log(2.0 if ln.lux == 5 else 20.0)}) for ln in lines]
    assert light_limit(measured) == pytest.approx(np.sqrt(2.0 * 20.0), rel=1e-3)
    dim_lit = [dataclasses.replace(ln, evidence={**ln.evidence, "log_lux": np.log(2.0 if ln.lux == 5 else (3.0 if k % 5 == 0 else 20.0))})
               for k, ln in enumerate(lines)]
    assert light_limit(dim_lit) == pytest.approx(3.0, rel=1e-3)  # a fifth of the lit lines measure 3 lux: the limit goes below them
    calibrate(measured, tmp_path / "model.json", tmp_path / "report", target_risk=0.05)
    assert json.loads((tmp_path / "model.json").read_text())["dim_lux"] == pytest.approx(6.32, abs=0.01)
    assert "measured less than 6.32 lux" in (tmp_path / "report" / "calibration.md").read_text()
    calibrate(lines, tmp_path / "unlit.json", tmp_path / "report", target_risk=0.05)
    assert "dim_lux" not in json.loads((tmp_path / "unlit.json").read_text())


def test_answer_lines_are_matched_to_their_closest_reference_line() -> None:
    matched = match_lines("the quick brown\nfox jumps over\n", [{"text": "fox jumps ovor"}, {"text": "the quick brown"}])
    assert matched[0]["line_cer"] == round(1 / 14, 4) and matched[0]["line_ref_chars"] == 14
    assert matched[1]["line_cer"] == 0.0


def test_calibrate_pools_the_lines_of_several_suites_and_names_them(tmp_path: Path) -> None:
    from darkread.cli import main

    def suite(root: Path, line_cer: float) -> Path:
        for i in range(24):
            folder = root / "eval_runs" / "on-change" / f"{i:03d}_lux5_still"
            folder.mkdir(parents=True)
            lines = [{"text": "a line", "line_cer": line_cer if j % 2 else 0.0, "line_ref_chars": 20,
                      "evidence": {"ocr_min": 0.2 if j % 2 else 0.9, "ocr_mean": 0.5 if j % 2 else 0.95}} for j in range(4)]
            (folder / "result.json").write_text(json.dumps({"name": folder.name, "lux": 5.0, "motion": "still", "kind": "words",
                                                            "darkread": {"text": "a line", "cer": 0.1, "lines": lines}}))
        return root

    first, second = suite(tmp_path / "a", 0.3), suite(tmp_path / "b", 0.5)
    out = tmp_path / "report"
    assert main(["eval", "calibrate", str(first), "--also", str(second), "--out", str(out),
                 "--model-out", str(tmp_path / "m.json")]) == 0
    doc = json.loads((tmp_path / "m.json").read_text())
    assert doc["suites"] == [f"{first} (96 lines)", f"{second} (96 lines)"]
    assert "Lines from:" in (out / "calibration.md").read_text()
    assert main(["eval", "calibrate", str(first), "--also", str(tmp_path / "none"), "--out", str(out),
                 "--model-out", str(tmp_path / "m.json")]) != 0


def test_a_model_is_checked_on_lines_it_was_not_fitted_on(tmp_path: Path) -> None:
    model, _ = calibrate(synthetic_lines(seed=3), tmp_path / "model.json", tmp_path / "report", target_risk=0.05)
    unseen = synthetic_lines(n=400, seed=9)  # other lines of the same law: calibrated there too
    result = check(unseen, model)
    assert result.lines == 400 and result.recordings == 400 and result.held_lines == len(split(unseen)[1])
    assert result.ece < 0.08 and result.held_ece is not None and 0.3 < result.right_share < 0.7
    overconfident = model.__class__(**{**model.__dict__, "intercept": model.intercept + 4.0})
    assert check(unseen, overconfident).ece > 0.2  # a model sure of everything is told so
    with pytest.raises(ValueError, match="evaluate the suite first"):
        check([], model)


def test_check_confidence_names_a_suite_without_results(tmp_path: Path, capsys) -> None:
    from darkread.cli import main

    assert main(["eval", "check-confidence", str(tmp_path)]) != 0
    err = capsys.readouterr().err
    assert "no results in" in err and "darkread eval run" in err and "Traceback" not in err


def test_pages_of_glasses_that_shed_get_a_weight_and_a_threshold_of_their_own(tmp_path: Path) -> None:
    """Lines of starved pages (evidence ``edge_shed``) leave the model of pages that kept up as it was,
    fit the shedding level's weight with the rest held, and set each level's threshold."""
    from dataclasses import replace

    from darkread.cloud.confidence import FEATURES, judge
    from darkread.lab.eval.calibrate import fit_model, model_json

    kept_up = [replace(ln, evidence={**ln.evidence, "edge_shed": 0.0}) for ln in synthetic_lines()]
    rng = np.random.default_rng(5)
    starved = []
    for k, line in enumerate(synthetic_lines(300, seed=4)):  # the same law, but level 3 makes half the sure lines wrong
        wrong = line.cer > 0 or rng.random() < 0.5
        starved.append(replace(line, recording=f"{k:03d}_s", cer=0.3 if wrong else 0.0, evidence={**line.evidence, "edge_shed": 3.0}))
    alone = fit_model(kept_up, target_risk=0.05)
    both = fit_model(kept_up + starved, target_risk=0.05)
    shed = FEATURES.index("edge_shed")
    assert both.weights[:shed] == alone.weights[:shed] and both.intercept == alone.intercept
    assert both.answer_threshold == alone.answer_threshold and alone.shed_thresholds == ()
    assert both.weights[shed] < 0 and (both.mean[shed], both.scale[shed]) == (0.0, 1.0)
    (level, threshold), = both.shed_thresholds
    assert level == 3 and threshold > both.answer_threshold
    sure = {"ocr_min": 0.95, "ink_solid": 0.3, "log_head_speed": 2.0}
    assert judge({**sure, "edge_shed": 0.0}, both).confidence == judge(sure, alone).confidence
    assert judge({**sure, "edge_shed": 3.0}, both).confidence < judge(sure, both).confidence
    assert ConfidenceModel.from_json(json.loads(model_json(both, {}))).shed_thresholds == both.shed_thresholds


def test_pages_measured_dim_get_a_threshold_of_their_own_when_one_threshold_lets_them_through() -> None:
    """Dim pages whose sure-looking lines are wrong twice as often: their own threshold holds them at the
    target risk, lit pages keep the model's, and the threshold survives the JSON."""
    from dataclasses import replace

    from darkread.cloud.confidence import judge
    from darkread.lab.eval.calibrate import fit_model, model_json
    from darkread.lab.eval.selective import weighted_cer

    rng = np.random.default_rng(8)
    lines = []
    for line in synthetic_lines(900, seed=6):
        dim_page = line.lux == 5
        wrong = line.cer > 0 or (dim_page and rng.random() < 0.12)
        lines.append(replace(line, cer=0.3 if wrong else 0.0, evidence={**line.evidence, "ink_solid": 0.2,
                                                                         "log_lux": np.log(2.0 if dim_page else 30.0)}))
    model = fit_model(lines, target_risk=0.05)
    assert model.dim_lux is not None and model.dim_threshold is not None and model.dim_threshold > model.answer_threshold
    dim_lines = [ln for ln in lines if ln.lux == 5]
    answered = [ln for ln in dim_lines if judge(ln.evidence, model).status == "read"]
    assert 0 < len(answered) < len(dim_lines) and weighted_cer(answered) <= 0.05
    lit = {"ocr_min": 0.6, "ink_solid": 0.2, "log_head_speed": 2.0, "log_lux": np.log(30.0)}
    assert model.threshold_for(lit) == model.answer_threshold
    assert model.threshold_for({**lit, "log_lux": np.log(2.0)}) == model.dim_threshold
    assert ConfidenceModel.from_json(json.loads(model_json(model, {}))).dim_threshold == model.dim_threshold
