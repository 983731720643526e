"""The evaluation suite: synthetic recordings over light, text, font, size and motion, fixed seeds.

Every recording is written by ``darkread.models.synth.recording.write_recording`` with a fully
fixed ``RecordingSpec`` (nothing left to chance but the seeded generator), plus ``spec.json``
(that spec, so the RGB baseline can re-create the scene) and ``suite.json`` at the suite root.

Axes: lux 1000/100/30/10/5; text kinds letters/words/pangram/paragraph; font families DejaVu Sans
and STIX General (training) and Roboto (held out of training); x-heights 7-12 event pixels;
motion still/normal/walking. The full suite crosses lux x motion x kind (fonts and x-heights
rotate through that grid), adds an x-height x font sweep and a block of 30-lux paragraphs (the
paper's headline condition); ``small`` varies one axis at a time around a base condition, for CI
and quick looks.

Every recording ends when the reader has read the page once (``read_once``; ``seconds`` is only
the upper bound), so the text the recording shows is exactly ``text.txt``, and words and
paragraphs come from the corpus part never used for training (``split="val"``).
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, replace
from fnmatch import fnmatch
from functools import partial
from pathlib import Path

from darkread.edge.calibrate.sensor_profile import load_sensor_profile
from darkread.edge.sources.evk4.bias_profiles import FACTORY, profile_offsets
from darkread.lab.jobs import run_jobs
from darkread.lab.synth.rgb_camera import SPEC_NAME
from darkread.lab.synth.simulators import simulator_for
from darkread.models.synth.fonts import FACES
from darkread.models.synth.motion import MOTION_REGIMES
from darkread.models.synth.recording import RecordingSpec, write_recording
from darkread.models.synth.sensor import K_BAND_HZ_PER_CHIP_LUX, K_LIMITS, REGIMES, GroundedSensorParams, with_standard_laws

logger = logging.getLogger(__name__)

SUITE_NAME = "suite.json"
LUX_LEVELS: tuple[float, ...] = (1000.0, 100.0, 30.0, 10.0, 5.0)
TEXT_KINDS: tuple[str, ...] = ("letters", "words", "pangram", "paragraph")
FONTS: tuple[str, ...] = ("DejaVu Sans", "STIX General", "Roboto")  # Roboto: held out of training
HELD_OUT_FONTS: tuple[str, ...] = ("Roboto",)
XHEIGHTS_PX: tuple[float, ...] = (7.0, 8.0, 9.0, 10.0, 11.0, 12.0)
MOTIONS: tuple[str, ...] = ("still", "normal", "walking")
BASE_SEED = 20250611


@dataclass(frozen=True)
class SuiteEntry:
    name: str
    lux: float
    motion: str
    kind: str
    font: str
    xheight_px: float
    seconds: float
    n_lines: int
    line_chars: int
    seed: int
    read_once: bool = True
    split: str = "val"
    scanpath: str = "model"  # "human": the shipped real reader's fixations replayed on the page
    simulator: str = "darkread"  # "hesim": the same scene turned into events by hesim-3d (lab/synth/hesim_sensor.py)
    regime: str = "standard"  # our simulator's sensor regime (sensor.REGIMES), e.g. "fast-photoreceptor"
    sensor_profile: str | None = None  # grounded: drawn around this measured sensor profile (calibrate sensor)
    motion_regime: str = "standard"  # the head motion's draws (motion.MOTION_REGIMES), e.g. "strong"
    bias_profile: str = FACTORY  # grounded: the IMX636 biases it is made with (edge/sources/evk4/bias_profiles.py)
    k_hz_per_chip_lux: float | None = None  # grounded: the photoreceptor's K fixed (None: drawn over its band)
    standard_laws: tuple[str, ...] = ()  # grounded: laws put back to the standard model's (attribution)

    def recording_spec(self):  # -> RecordingSpec (imported lazily: the synth engine is heavy)

        return RecordingSpec(
            lux=self.lux, motion=self.motion, kind=self.kind, seconds=self.seconds, seed=self.seed, font=self.font,
            xheight_px=self.xheight_px, n_lines=self.n_lines, line_chars=self.line_chars,
            description=f"darkread evaluation suite: {self.name}", split=self.split, read_once=self.read_once,
            scanpath=self.scanpath, simulator=self.simulator, regime=self.regime, sensor_profile=self.sensor_profile,
            motion_regime=self.motion_regime, bias_profile=self.bias_profile, k_hz_per_chip_lux=self.k_hz_per_chip_lux,
            standard_laws=tuple(self.standard_laws),
        )


SECONDS_PER_LINE_CAP = 2.5  # the upper bound of a read-once recording; readers need ~1-1.5 s per line
# the real reader (oz) makes 10-19 fixations per line of 67 characters, replayed on a line of 28
HUMAN_SECONDS_PER_LINE_CAP = 4.5
HUMAN_BLOCK: tuple[tuple[float, str], ...] = tuple((lux, motion) for lux in (30.0, 10.0) for motion in MOTIONS)


def _entry(index: int, lux: float, motion: str, kind: str, font: str, xheight: float, *, small: bool,
           scanpath: str = "model") -> SuiteEntry:
    n_lines, line_chars = (3, 20) if small else ((4, 28) if kind == "paragraph" else (3, 28))
    seconds = 1.0 + (HUMAN_SECONDS_PER_LINE_CAP if scanpath == "human" else SECONDS_PER_LINE_CAP) * n_lines
    slug = font.lower().replace(" ", "")
    name = f"{index:03d}_lux{lux:g}_{motion}_{kind}_{slug}_xh{xheight:g}" + ("_human" if scanpath == "human" else "")
    return SuiteEntry(name, float(lux), motion, kind, font, float(xheight), seconds, n_lines, line_chars, BASE_SEED + index,
                      scanpath=scanpath)


def suite_entries(*, small: bool = False) -> list[SuiteEntry]:
    """The suite's recordings, in a fixed order with fixed seeds."""
    conditions: list[tuple[float, str, str, str, float]] = []
    if small:
        base = (100.0, "normal", "pangram", "DejaVu Sans", 10.0)
        conditions += [(lux, "normal", "pangram", "DejaVu Sans", 10.0) for lux in LUX_LEVELS]
        conditions += [(lux, motion, "pangram", "DejaVu Sans", 10.0) for lux in (30.0, 5.0) for motion in ("still", "walking")]
        conditions += [(100.0, "normal", kind, "DejaVu Sans", 10.0) for kind in TEXT_KINDS if kind != base[2]]
        conditions += [(100.0, "normal", "pangram", font, 10.0) for font in FONTS if font != base[3]]
        conditions += [(100.0, "normal", "pangram", "DejaVu Sans", xh) for xh in (7.0, 8.0, 12.0)]
    else:
        k = 0
        for lux in LUX_LEVELS:
            for motion in MOTIONS:
                for kind in TEXT_KINDS:
                    conditions.append((lux, motion, kind, FONTS[k % len(FONTS)], XHEIGHTS_PX[(k * 5) % len(XHEIGHTS_PX)]))
                    k += 1
        conditions += [(100.0, "normal", "paragraph", font, xh) for font in FONTS for xh in XHEIGHTS_PX]
        conditions += [(30.0, motion, "paragraph", font, 10.0) for motion in MOTIONS for font in FONTS]
    entries = [_entry(i, *c, small=small) for i, c in enumerate(conditions)]
    if not small:  # real-scanpath block (appended: the seeds and names above stay as they were)
        entries += [_entry(len(entries) + i, lux, motion, "paragraph", "DejaVu Sans", 10.0, small=False, scanpath="human")
                    for i, (lux, motion) in enumerate(HUMAN_BLOCK)]
    return entries


# The second-simulator check: the suite's own grid recordings (lux x motion x kind, first in the
# suite) at these levels and of these kinds, every motion: 6 per level, same names, seeds and texts.
SIMULATOR_CHECK_LUX: tuple[float, ...] = (30.0, 10.0, 5.0)
SIMULATOR_CHECK_KINDS: tuple[str, ...] = ("words", "paragraph")
SUBSETS: tuple[str, ...] = ("simulator-check",)


def simulator_check_entries() -> list[SuiteEntry]:
    """The recordings of the full suite the second simulator re-makes (``--subset simulator-check``)."""
    grid = len(LUX_LEVELS) * len(MOTIONS) * len(TEXT_KINDS)
    return [e for e in suite_entries()[:grid] if e.lux in SIMULATOR_CHECK_LUX and e.kind in SIMULATOR_CHECK_KINDS]


def spec_document(entry: SuiteEntry) -> dict:
    """What ``spec.json`` holds: the recording spec, without the fields left at their defaults that
    older suites did not have (so their recordings stay complete)."""
    doc = json.loads(json.dumps(asdict(entry.recording_spec())))  # as spec.json reads back (tuples as lists)
    for key, default in (("scanpath", "model"), ("scanpath_file", None), ("simulator", "darkread"), ("sensor_profile", None),
                         ("motion_regime", "standard"), ("k_hz_per_chip_lux", None),
                         ("standard_laws", [])):
        if doc.get(key) == default:
            doc.pop(key, None)
    return doc


def _write_entry(out: Path, entry: SuiteEntry) -> None:
    """Write one recording unless it is already complete (runs in a worker process)."""

    folder = out / entry.name
    spec_doc = spec_document(entry)
    spec_path = folder / SPEC_NAME
    if spec_path.is_file() and json.loads(spec_path.read_text()) == spec_doc and (folder / "meta.json").is_file():
        return
    spec = entry.recording_spec()
    write_recording(folder, spec, progress=False, simulator=simulator_for(spec.simulator))
    spec_path.write_text(json.dumps(spec_doc, indent=1))  # last: marks the recording complete


def in_font(entry: SuiteEntry, family: str) -> SuiteEntry:
    """The same recording (seed, light, motion, text kind, x-height) set in another font family;
    its name says the new family and ends in ``_as_<old family>``, so it pairs with the original."""
    old, new = _slug(entry.font), _slug(family)
    stem, _, tail = entry.name.partition(f"_{old}_")
    return replace(entry, font=family, name=f"{stem}_{new}_{tail}_as_{old}")


def _slug(family: str) -> str:
    return family.lower().replace(" ", "")


def select_entries(*, small: bool = False, match: str | Sequence[str] | None = None, subset: str | None = None,
                   simulator: str = "darkread", font: str | None = None, regime: str = "standard",
                   sensor_profile: str | None = None, motion_regime: str = "standard", biases: str = FACTORY,
                   k: float | None = None, standard_laws: Sequence[str] = ()) -> list[SuiteEntry]:
    """The recordings ``make_suite`` writes, in order (its arguments, checked there)."""
    entries = simulator_check_entries() if subset == "simulator-check" else suite_entries(small=small)
    entries = [replace(e, simulator=simulator, regime=regime, sensor_profile=sensor_profile,
                       motion_regime=motion_regime, bias_profile=biases, k_hz_per_chip_lux=k,
                       standard_laws=tuple(standard_laws)) for e in entries]
    if match:
        patterns = [match] if isinstance(match, str) else list(match)
        entries = [e for e in entries if name_matches(e.name, patterns)]
        if not entries:
            raise ValueError(f"--match {' '.join(patterns)}: no recording of the suite has such a name")
    if font is not None:
        entries = [in_font(e, font) for e in entries if e.font != font]
    return entries


def name_matches(name: str, patterns: Sequence[str]) -> bool:
    """Whether a recording's name matches any of ``patterns`` (a shell pattern, or a part of the name):
    ``--match`` of make-suite and of run."""
    return any(fnmatch(name, m) or m in name for m in patterns)


def make_suite(
    out: str | Path, *, small: bool = False, progress: bool = True, only: int | None = None, jobs: int = 1,
    match: str | Sequence[str] | None = None, subset: str | None = None, simulator: str = "darkread",
    font: str | None = None, regime: str = "standard", sensor_profile: str | None = None,
    motion_regime: str = "standard", biases: str = FACTORY, k: float | None = None, standard_laws: Sequence[str] = (),
) -> list[SuiteEntry]:
    """Write the suite under ``out`` with ``jobs`` worker processes; complete recordings (their
    ``spec.json`` matches) are kept, so an interrupted run resumes. ``match``: only the recordings
    whose name matches this shell pattern (e.g. ``*lux30_*_human``), or any of several; ``subset``: a named part of the
    full suite (``simulator-check``); ``simulator``: what turns the scenes into events; ``font``: every
    selected recording not already in this family made again in it (``in_font``), to tell what a
    font costs from what a scene does; ``regime``: our simulator's sensor regime (the same scenes and
    draws; ``fast-photoreceptor``: what the photoreceptor's speed in the dark decides); ``sensor_profile``:
    the grounded sensor drawn around a measured profile (``darkread calibrate sensor``) instead of its band;
    ``motion_regime``: the head motion's draws (``quiet``, ``central``, ``strong``: the grounded bands'
    ends and centre); ``biases``: the IMX636 bias profile (grounded: ``factory`` or ``dark``); ``k``: the
    grounded photoreceptor's K fixed (Hz per chip-lux) instead of drawn over its band, every other draw
    the same; ``standard_laws``: grounded laws put back to the standard model's (``sensor.STANDARD_LAWS``),
    one at a time to attribute the difference between the two models."""
    from tqdm import tqdm


    families = sorted({face.family for face in FACES})
    if font is not None and font not in families:
        raise ValueError(f"--font {font!r}: use one of {', '.join(families)}")

    simulator_for(simulator)  # an unknown name, or hesim-3d missing here: one line before any work

    if regime not in REGIMES:
        raise ValueError(f"--regime {regime!r}: use one of {', '.join(REGIMES)}")
    if regime != "standard" and simulator != "darkread":
        raise ValueError(f"--regime {regime} is our simulator's; leave out --simulator {simulator}")
    if sensor_profile is not None:
        if regime != "grounded":
            raise ValueError(f"--sensor-profile is drawn from by the grounded regime: add --regime grounded (not {regime})")
        sensor_profile = str(Path(sensor_profile).resolve())
        load_sensor_profile(sensor_profile)  # missing or wrong: one line before any work
    if motion_regime not in MOTION_REGIMES:
        raise ValueError(f"--motion-regime {motion_regime!r}: use one of {', '.join(MOTION_REGIMES)}")
    profile_offsets(biases)  # an unknown profile: one line
    if (biases != FACTORY or k is not None or standard_laws) and regime != "grounded":
        raise ValueError(f"--biases, --k and --standard-law are the grounded sensor's: add --regime grounded (not {regime})")
    with_standard_laws(GroundedSensorParams(), tuple(standard_laws))  # an unknown law: one line
    if k is not None and not K_LIMITS[0] <= k <= K_LIMITS[1]:
        raise ValueError(f"--k {k:g}: a photoreceptor K in {K_LIMITS[0]:g}..{K_LIMITS[1]:g} Hz per chip-lux "
                         f"(the published band is {K_BAND_HZ_PER_CHIP_LUX[0]:g}-{K_BAND_HZ_PER_CHIP_LUX[1]:g})")
    if subset is not None and subset not in SUBSETS:
        raise ValueError(f"--subset {subset!r}: use one of {', '.join(SUBSETS)}")
    if subset is not None and small:
        raise ValueError("--subset picks from the full suite; leave out --small")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    entries = select_entries(small=small, match=match, subset=subset, simulator=simulator, font=font, regime=regime,
                             sensor_profile=sensor_profile, motion_regime=motion_regime, biases=biases, k=k,
                             standard_laws=standard_laws)
    entries = entries[:only]
    (out / SUITE_NAME).write_text(
        json.dumps({"small": small, "subset": subset, "simulator": simulator, "regime": regime, "font": font,
                    "sensor_profile": sensor_profile, "motion_regime": motion_regime, "biases": biases,
                    "k_hz_per_chip_lux": k, "standard_laws": list(standard_laws),
                    "created": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                    "recordings": [asdict(e) for e in entries]}, indent=1)
    )
    bar = tqdm(total=len(entries), desc="recordings", unit="rec", disable=not progress)
    run_jobs(partial(_write_entry, out), entries, jobs, bar.update)
    bar.close()
    return entries


def load_suite(suite_dir: str | Path) -> list[Path]:
    """Recording folders of a suite (every sub-folder with a ``text.txt``), in name order."""
    root = Path(suite_dir)
    if not root.is_dir():
        raise FileNotFoundError(f"{root}: no such suite directory")
    folders = sorted(p for p in root.iterdir() if p.is_dir() and (p / "text.txt").is_file())
    if not folders:
        raise FileNotFoundError(f"{root}: no recordings (sub-folders with text.txt); make one with `darkread eval make-suite`")
    return folders
