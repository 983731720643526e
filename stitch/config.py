"""How the stitcher behaves: every threshold in one frozen dataclass."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class StitchConfig:
    """Thresholds of the stitcher. Pixel figures are sensor pixels of the IMX636 window (x-height ~10 px).

    Line segmentation (return sweeps):
      sweep_min_px          a return sweep moves the gaze left by at least this much (px); forward
                            saccades (7-9 letters, ~70 px) and small regressions stay below it.
      sweep_line_fraction   ... and by at least this fraction of the current line's gaze extent, so a
                            long regression mid-line does not end it.
      sweep_max_rise_px     a left jump that also moves the gaze *up* by more than this (median of
                            the samples after vs before) is a regression to an earlier line, not a
                            return sweep (a sweep goes down a pitch; ~2 pitches above that, as
                            vertical gaze noise of 30-45 px would otherwise veto real sweeps).
      sweep_context_frames  gaze samples before the jump; the rightmost stands for the launch point.
      sweep_confirm_frames  further samples after the jump whose median (with the first) must stay
                            left of the launch point by half the needed jump: a single wild sample
                            does not start a line. Adds this many frames of latency to the
                            incremental stitcher.
      min_line_frames       no second break within this many frames of the last one (an undershooting
                            sweep followed by its corrective saccade is one break).
      sweep_sample_ms       the rule sees at most one frame per this many ms (the others ride along
                            with the frame before): at 300 frames/s four frames span 13 ms, less than
                            a saccade between two tracker rows, so launch and landing never appeared
                            in one look (1 of 4 lines found); the frame counts above count these samples.
    Registration:
      search_radius_px      correlation search around the predicted position (head tremor and the
                            drift change between two frames stay well inside; half a line pitch
                            would allow locking on the neighbouring line).
      drift_window_frames   a line through the head-motion corrections of this many recent frames
                            predicts the next frame's place (tremor averages out, drift is followed)
                            once they span 60 ms; frames 3 ms apart (busy text) give their median
                            (a slope over a few ms is jitter, not drift).
      scene_anchor_frames   frames that carry the scene's motion (``FrameRecord.scene_px``, measured
                            from all the sensor's events on the glasses) are predicted from it
                            instead: page position - sensor position + scene offset stays put while
                            the head moves, so its median over this many recent frames minus the
                            new frame's scene offset is where the frame lands. One fused view per
                            fixation gives the line fit a few points a second: across a return
                            sweep it missed by half a window; 0 turns it off.
      scene_gap_ms          ... for a frame this long after the last registered one: frames a few
                            milliseconds apart follow the head better by their own corrections (the
                            scene's motion is coarser, docs/head_motion.md), the scene bridges the gaps.
      wide_search_px        a frame whose best match lies on the rim of the search window, or scores
                            ``weak_match_drop`` below the recent matches' median, is searched again
                            this far around the prediction (the head moved more than predicted, and
                            the usual search found the neighbouring line); 0 turns it off.
      wide_min_known        ... and its peak is taken only where this share of the frame lies on
                            seen content: 40 px from the prediction a frame can sit on a sliver of
                            the page, where a few strokes correlate perfectly (score ~1) with
                            anything; such a frame goes to the anchor search instead.
      doubtful_match_drop   a match this far below the recent median (but not weak) is searched
                            wide too, and the wide peak taken only on the same line (fewer than
                            ``ambiguity_rows`` rows from it) and ``anchor_gain`` better: with the
                            scene's offset a few px off per frame, a word matched a letter off
                            still scores above the weak match's drop, and each such frame moves the
                            next prediction further off. A line's worth up or down stays the weak
                            match's test (in dim light a wide peak a line away can beat a right but
                            noisy match); stitch/README.md has the pages. 0 turns it off.
      ambiguity_rows        ... where matches at least this many rows from the peak are the
                            neighbouring lines' (text lines look alike to a correlation) ...
      ambiguity_margin      ... which the peak must beat by this much; otherwise the frame is dropped
                            rather than risk blending it a line pitch off.
      anchor_search_px      a frame that found no match near the prediction (no overlap there, a
                            rejected re-search, or a score below ``anchor_trigger_score`` or
                            ``weak_match_drop`` under the recent ones) is matched whole against
                            everything seen this far around it: walking bobs the head tens of pixels
                            between frames, and a frame placed at a prediction that missed would
                            start a second copy of lines already stitched. 0 turns it off.
      anchor_min_score      ... that place is taken if it scores at least this, beats the match near
      anchor_gain           the prediction by ``anchor_gain`` and every place a line above or below
                            by ``ambiguity_margin``;
      anchor_known_fraction ... and only places where this share of the frame lies on seen content
                            (and the page there holds about as much ink variation) are considered;
      anchor_slack_px       ... and the place must lie within the head's reach of the last registered
      max_head_speed_px_s   frame: this slack plus this speed times the time since (a walking bob
                            moves the page up to ~400 px/s in the sensor; noise in low light matches
                            a stretch 150 px away 50 ms later).
      min_match_score       normalised correlation (TM_CCOEFF_NORMED) below which a frame is dropped.
      min_overlap_fraction  share of the frame that must overlap what the page already shows for a
                            correlation to be trusted; otherwise the frame goes to its predicted place.
      roll_step_deg         the frame is also tried rotated by +- this around the recent head roll
                            (parabola-refined): the page turns in the sensor as the head rolls.
                            0 searches shifts only.
      roll_every_frames     the rotation is searched on every n-th registered frame (head roll is
                            slow; each search costs two more correlations).
      roll_window           the median of this many recent roll measurements places the frames.
      max_roll_deg          roll estimates are clamped to +- this.
      blur_sigma_px         Gaussian blur before correlation: widens the peak, tames speckle.
      min_ink_fraction      frames with less ink than this (blank reconstructions) are dropped.
      subpixel              refine the correlation peak to a fraction of a pixel and blend the frame
                            in at that position (bilinear), instead of at the nearest pixel.
    Accumulation:
      alpha                 smallest blending weight of a new frame in the running average (the
                            alpha channel): frames average evenly (1/n) until 1/n falls below it,
                            later ones blend with ``alpha`` so slow changes are followed. 0 (plain
                            average): at 300 frames/s a floor of 0.08 kept only the last ~40 ms of
                            frames, so a correctly registered second pass replaced the first.
      improvement_tolerance a pixel takes the new frame only where the frame's match score is at
                            least the best score saved for that pixel minus this (improvement mask).
      replace_margin        where the frame's score beats the saved one by more than this, the
                            pixel starts afresh from the frame (drops what a frame placed without
                            registration, score 0, put there).
      taper_sigma_rows      vertical Gaussian (rows) weighting each frame's rows around its centre:
                            the fixated line counts most, neighbouring lines less.
    De-warp (KLT between a finished line and the page above it):
      dewarp_degree         polynomial degree in x of the line's displacement (0 = offset, 1 = offset
                            + slope, i.e. a small tilt of the whole line).
      dewarp_max_shift_px   larger corrections are distrusted and skipped.
      dewarp_min_points     tracked features needed to estimate a warp.
      dewarp_min_gain       the warp is undone only if the strip's correlation with the page where
                            they overlap rises by at least this much.
    Page:
      ink_threshold         alpha-averaged ink probability above which a page pixel is ink.
      min_component_px      ink specks smaller than this many pixels are removed from the page.
      deskew_max_deg        the page is turned so its text lines run horizontally (row-profile
                            sharpness searched within +- this); the page keeps the first frame's
                            orientation otherwise. 0 turns it off.
      deskew_min_deg        smaller skews are left alone (resampling blurs a little).
      min_views             page pixels seen by fewer frames than this stay paper (window borders
                            seen once would otherwise keep that frame's speckle).
      line_gap_px           a line's box spans its ink columns; a gap wider than this cuts off stray ink.
      grey_saturation       the grey page (what OCR reads) is black where the ink probability reaches
                            this, and shades below it: averaged strokes keep their sub-pixel shape,
                            which a hard threshold of bold U-Net strokes loses (e/o, a/o, i/l).
      ink_percentile        ... or where it reaches this percentile of the page's probability above
      faint_ink             this, when that is lower (dim light: frames that each find half the strokes
      min_ink_level         average to grey), but not below this; the ink threshold scales alike
                            (what it changed: stitch/README.md).
    """

    sweep_min_px: float = 140.0
    sweep_line_fraction: float = 0.5
    sweep_max_rise_px: float = 60.0
    sweep_context_frames: int = 4
    sweep_confirm_frames: int = 2
    min_line_frames: int = 4
    sweep_sample_ms: float = 20.0
    search_radius_px: int = 16
    drift_window_frames: int = 6
    scene_anchor_frames: int = 3
    scene_gap_ms: float = 50.0
    wide_search_px: int = 40
    weak_match_drop: float = 0.2
    wide_min_known: float = 0.3
    doubtful_match_drop: float = 0.1
    anchor_search_px: int = 200
    anchor_trigger_score: float = 0.5
    anchor_min_score: float = 0.5
    anchor_gain: float = 0.1
    anchor_known_fraction: float = 0.5
    anchor_slack_px: float = 24.0
    max_head_speed_px_s: float = 400.0
    ambiguity_rows: int = 10
    ambiguity_margin: float = 0.1
    min_match_score: float = 0.25
    min_overlap_fraction: float = 0.1
    roll_step_deg: float = 0.5
    roll_every_frames: int = 3
    roll_window: int = 5
    max_roll_deg: float = 5.0
    blur_sigma_px: float = 1.2
    min_ink_fraction: float = 0.003
    subpixel: bool = True
    alpha: float = 0.0
    improvement_tolerance: float = 0.15
    replace_margin: float = 0.3
    taper_sigma_rows: float = 22.0
    dewarp_degree: int = 1
    dewarp_max_shift_px: float = 8.0
    dewarp_min_points: int = 12
    dewarp_min_gain: float = 0.005
    ink_threshold: float = 0.4
    min_component_px: int = 2
    min_views: int = 2
    deskew_max_deg: float = 15.0
    deskew_min_deg: float = 0.5
    line_gap_px: int = 30
    grey_saturation: float = 0.8
    ink_percentile: float = 99.0
    faint_ink: float = 0.05
    min_ink_level: float = 0.2

    def __post_init__(self) -> None:
        if self.sweep_confirm_frames < 0 or self.sweep_context_frames < 1 or self.min_line_frames < 1:
            raise ValueError("sweep_confirm_frames must be >= 0, sweep_context_frames and min_line_frames >= 1")
        if self.roll_every_frames < 1 or self.roll_window < 1:
            raise ValueError("roll_every_frames and roll_window must be >= 1")
        if self.scene_anchor_frames < 0:
            raise ValueError(f"scene_anchor_frames must be >= 0, got {self.scene_anchor_frames}")
        if self.drift_window_frames < 1:
            raise ValueError(f"drift_window_frames must be >= 1, got {self.drift_window_frames}")
        if self.search_radius_px < 0:
            raise ValueError(f"search_radius_px must be >= 0, got {self.search_radius_px}")
        if self.anchor_search_px < 0 or self.max_head_speed_px_s < 0 or self.anchor_slack_px < 0:
            raise ValueError("anchor_search_px, anchor_slack_px and max_head_speed_px_s must be >= 0")
        if not 0.0 <= self.alpha <= 1.0 or not 0.0 < self.ink_threshold < 1.0:
            raise ValueError("alpha must be in [0, 1] and ink_threshold in (0, 1)")
        if not 0.0 < self.grey_saturation <= 1.0:
            raise ValueError(f"grey_saturation must be in (0, 1], got {self.grey_saturation}")
        if not 0.0 <= self.ink_percentile <= 100.0 or not 0.0 <= self.faint_ink < 1.0:
            raise ValueError("ink_percentile must be in [0, 100] and faint_ink in [0, 1)")
        if not 0.0 < self.min_ink_level <= self.grey_saturation:
            raise ValueError(f"min_ink_level must be in (0, grey_saturation], got {self.min_ink_level}")
