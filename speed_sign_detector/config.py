"""Frozen configuration of every stage.

Each field carries its description and valid range in ``dataclasses.field`` metadata
(see :func:`setting`), so the ROS node declares its parameters from these classes
alone (one declaration, with descriptors and ranges) and every way of building a
config (code, YAML file, ROS parameters) is validated by the same rules. Flat parameters
and parameter files are read and written by :mod:`speed_sign_detector.config_parameters`.

Parameter names are ``<section>.<field>``, e.g. ``detector.min_radius_px``.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

from speed_sign_detector.errors import ConfigError


def setting(default: Any, description: str, *, low: float | None = None,
            high: float | None = None, choices: tuple[str, ...] | None = None) -> Any:
    """Declare a config field with its description and valid range (inclusive)."""
    return field(default=default, metadata={
        'description': description, 'low': low, 'high': high, 'choices': choices})


def parameter_name(config: Any, field_name: str) -> str:
    """The name a user gives a config field: ``section.field`` for a stage's config
    (``detector.min_radius_px``), the bare field name for the top-level ones."""
    for section, config_class in SECTIONS.items():
        if type(config) is config_class:
            return f'{section}.{field_name}'
    return field_name


def validate(config: Any) -> None:
    """Check every field of a config dataclass against its declared range.

    Raises:
        ConfigError: naming the parameter as a user writes it (``detector.min_radius_px``),
            the value and the allowed range.
    """
    for item in dataclasses.fields(config):
        value = getattr(config, item.name)
        meta = item.metadata
        if dataclasses.is_dataclass(value):
            continue
        expected_type = type(item.default) if item.default is not dataclasses.MISSING else None
        if expected_type is float and isinstance(value, int) and not isinstance(value, bool):
            object.__setattr__(config, item.name, float(value))
            value = float(value)
        if expected_type is not None and not isinstance(value, expected_type):
            raise ConfigError(f'{parameter_name(config, item.name)} must be '
                              f'{expected_type.__name__}, got {value!r}')
        low, high, choices = meta.get('low'), meta.get('high'), meta.get('choices')
        if low is not None and value < low:
            raise ConfigError(f'{parameter_name(config, item.name)} = {value!r} is below '
                              f'its minimum {low}')
        if high is not None and value > high:
            raise ConfigError(f'{parameter_name(config, item.name)} = {value!r} is above '
                              f'its maximum {high}')
        if choices is not None and value not in choices:
            raise ConfigError(f'{parameter_name(config, item.name)} = {value!r} is not one '
                              f'of {", ".join(choices)}')


@dataclass(frozen=True)
class DetectorConfig:
    """Radial-symmetry detector (IVS 2011, sections III-A, III-B, III-D)."""

    min_radius_px: float = setting(3.5, 'Smallest radius voted for, in pixels (the inner '
                                   'edge of the red ring of an 11 px wide sign).',
                                   low=2.0, high=200.0)
    max_radius_px: float = setting(40.0, 'Largest sign radius searched, in pixels.',
                                   low=3.0, high=400.0)
    radius_bands: int = setting(4, 'Number of radius bands voted separately to recover '
                                'the size (section III-D).', low=1, high=8)
    gradient_threshold: float = setting(60.0, 'Minimum 3x3 Sobel gradient magnitude of '
                                        'an edge pixel, on the contrast scale (0..255) '
                                        'per pixel x 8.',
                                        low=0.0, high=2000.0)
    max_candidates: int = setting(7, 'Most candidates reported per frame.', low=1, high=64)
    block_size_px: int = setting(8, 'Block size of the max reduction, in pixels.',
                                 low=1, high=32)
    polarity: str = setting('both', 'Which side of an edge votes: '
                            'bright_inside (white disc in a dark ring), dark_inside, '
                            'or both (a sign\'s two concentric ring edges both vote, a '
                            'plain bright blob\'s one edge scores half: on gtsdb-dev '
                            'candidates on 281 of 284 limit signs against 269 with '
                            'bright_inside, for about half again the voting time on '
                            'llvmpipe).', choices=('bright_inside', 'dark_inside', 'both'))
    vote_profile: str = setting('tent', 'Weight of a vote across its spread: tent (1 on '
                                'the gradient line, falling linearly to 0 at +/- r tan(pi/8): '
                                'a sharp peak at the centre) or flat (the paper\'s uniform '
                                'spread: a plateau).', choices=('tent', 'flat'))
    dark_side_min_radius_px: float = setting(0.0, 'With bright_inside polarity, radius '
                                             'bands from this radius up vote toward both '
                                             'sides (the ring\'s outer edge against a '
                                             'brighter sky); 0 = never.', low=0.0,
                                             high=400.0)
    min_score: float = setting(0.0, 'Candidates scoring below this are not reported.',
                               low=0.0, high=1e9)
    contrast: str = setting('log', 'Gray scale the gradients are taken on: linear gray '
                            'levels, or log (gradients measure contrast ratios, so a sign in '
                            'shade has the edges it has in sunlight).',
                            choices=('linear', 'log'))
    log_offset_gray: float = setting(16.0, 'Offset c of the log scale '
                                     '255 ln((I + c) / c) / ln((255 + c) / c): limits how '
                                     'much sensor noise in deep shadow is amplified.',
                                     low=1.0, high=255.0)
    thin_edges: bool = setting(True, 'Keep only edge pixels that are local maxima of the '
                               'gradient magnitude along the gradient (non-maximum '
                               'suppression): thinner edges, fewer votes.')
    edge_support: int = setting(1, 'An edge pixel votes only when at least this many of '
                                'its 8 neighbours are edge pixels with a gradient direction '
                                'within 30 degrees (contours, not isolated texture).',
                                low=0, high=8)
    level_min_radius_px: float = setting(4.0, 'A radius band votes on the coarsest pyramid '
                                         'level (2x2 box averages) on which its smallest '
                                         'radius still spans this many level pixels.',
                                         low=1.0, high=100.0)
    max_pyramid_level: int = setting(2, 'Coarsest pyramid level used for voting (0 = vote '
                                     'at full resolution only).', low=0, high=6)
    vote_pixels_per_radius: float = setting(2.0, 'A band votes into an image (a pyramid '
                                            'level at least as coarse as its edges) whose '
                                            'pixel is at most its smallest radius / this: '
                                            'coarser vote images for large radii, fewer '
                                            'fragments; centres are refined to sub-pixel. '
                                            '0 = vote at the edge level. 2 keeps the '
                                            'smallest band (signs 11-16 px wide) at full '
                                            'resolution: on gtsdb-dev 7 more limit signs '
                                            'found than with 1.75, for about 8 ms more per '
                                            '640x480 frame on llvmpipe.',
                                            low=0.0, high=100.0)
    voting_edge_radius_ratio: float = setting(1.0, 'Candidates report the voting radius '
                                              '(harmonic mean voting distance) divided by '
                                              'this. 1 = the radius of the edges that voted '
                                              '(with both polarities about 0.77 of the outer '
                                              'radius on GTSDB, between the red ring\'s inner '
                                              'and outer edge; with bright_inside mostly the '
                                              'inner edge, about 0.7).', low=0.1, high=1.0)
    vote_method: str = setting('auto', 'How the GL backend adds the votes: raster (the '
                               'paper: one triangle per edge, additive blending into float '
                               'targets), scatter (a compute pass adds each edge\'s '
                               'trapezoid to integer images with atomics; same votes, '
                               'bit-reproducible), or auto (scatter: the faster on every '
                               'renderer measured, llvmpipe and an NVIDIA H100).',
                               choices=('auto', 'raster', 'scatter'))
    suppression_factor: float = setting(1.0, 'Non-maximum suppression: a candidate closer '
                                        'than this many voting radii (the larger of the '
                                        'two) to a better one is the same sign and dropped.',
                                        low=0.0, high=10.0)
    enclosing_ring_ratio: float = setting(
        2.0, 'Non-maximum suppression keeps a candidate of at least this many times the '
        'radius of a better one whose centre lies inside it (within 0.6 of its radius): the '
        'ring of a large sign around its digits\' loops, which vote for circles of their own '
        '(0 = suppress it as any other).', low=0.0, high=10.0)
    detection_width_px: int = setting(
        960, 'Frames wider than this are scaled down to this width (area averaging, aspect '
        'kept) for detection, which then costs about the same at any camera resolution; '
        'the classifier still reads each candidate from the full-resolution pixels. The '
        'detector\'s radii (min_radius_px, max_radius_px, ...) are pixels of the scaled '
        'frame: with 960, a 1920x1080 camera\'s signs are found from radius 7 px '
        '(2 x min_radius_px) to 80 px (2 x max_radius_px) in its own pixels. Narrower '
        'frames (640x480, 816x480) are detected as they are. 0 = always at full '
        'resolution.', low=0, high=16384)
    roi_top_fraction: float = setting(
        0.0, 'Region of interest: signs are searched only in the band of rows from this '
        'fraction of the frame height (0 = the top row; e.g. 0.2 leaves out the sky) to '
        'roi_bottom_fraction.', low=0.0, high=1.0)
    roi_bottom_fraction: float = setting(
        1.0, 'Region of interest: signs are searched only down to this fraction of the '
        'frame height (1 = the bottom row; e.g. 0.8 leaves out the bonnet).',
        low=0.0, high=1.0)

    def __post_init__(self) -> None:
        validate(self)
        if self.max_radius_px <= self.min_radius_px:
            raise ConfigError(f'detector.max_radius_px ({self.max_radius_px}) must be '
                              f'larger than detector.min_radius_px ({self.min_radius_px})')
        if self.roi_bottom_fraction <= self.roi_top_fraction:
            raise ConfigError(f'detector.roi_bottom_fraction ({self.roi_bottom_fraction}) '
                              f'must be larger than detector.roi_top_fraction '
                              f'({self.roi_top_fraction})')


@dataclass(frozen=True)
class ClassifierConfig:
    """FFT template classifier (DAGM 2010)."""

    psr_threshold: float = setting(8.0, 'Peak-to-sidelobe ratio below which the answer is '
                                   '"no sign" (with a trained second opinion: below which '
                                   'the answer needs its clearer lead).', low=0.0,
                                   high=1000.0)
    second_opinion_psr_threshold: float = setting(
        6.0, 'With a trained second opinion, the PSR below which the answer is "no sign" '
        '(instead of psr_threshold); below psr_threshold the second opinion must then lead by '
        'second_opinion_low_psr_lead.', low=0.0, high=1000.0)
    second_opinion_low_psr_lead: float = setting(
        1.0, 'Least score lead of the second opinion for an answer whose PSR is below '
        'psr_threshold (it needs the bank\'s own min_lead above it).', low=0.0, high=10.0)
    second_opinion_overrule_lead: float = setting(
        1.2, 'Least score lead of the second opinion for answering a speed limit other than '
        'the one the correlation filters ranked first; with a weaker lead the answer is '
        'withheld, so that a value the two disagree on is not published.',
        low=0.0, high=10.0)
    second_opinion_certain_lead: float = setting(
        1.98, 'Least score lead of the second opinion (scores span -1 to +1) over its next '
        'label for answering a limit it was trained on real crops of where the other rules '
        'withhold the sign: the correlation\'s leader, or another label where that '
        'leader\'s PSR is below psr_threshold; never a sign read inverted, nor near a value '
        'without real crops in the correlation (SecondOpinion.certain_choice); above 2: '
        'never. Re-decided on recorded looks: 5 folds by track 0.9585 -> 0.9592 read right, '
        'gtsdb-dev scene folds 252 -> 254 of 284 signs, nothing more read as another limit '
        'there, in leave one value out or in the rendered designs (1.9: one more false '
        'limit, one more held-out 80 read as 60).', low=0.0, high=10.0)
    lit_face_min_margin: float = setting(
        0.75, 'Least PSR lead of a limit answer over every other limit in the correlation on '
        'a sign with a lit face (a glowing face in dark surroundings: an electronic sign '
        'with dark digits, or a painted one over-exposed at night); with a smaller lead '
        'the answer is withheld, the glow thinning the digits\' strokes toward another '
        'value. Re-decided on recorded looks: rendered designs (30 of each value and '
        'design, seeds 1 and 2) 8 -> 6 wrong each, dark-on-lit signs 0.931 -> 0.911 and '
        '0.929 -> 0.904 read right; gtsrb-dev 5 folds by track 4 of 4,480 crops withheld '
        'that were read right, none fewer read as another limit.', low=0.0, high=1000.0)
    min_margin: float = setting(0.25, 'PSR lead over the best other label below which an '
                                'end-of-limit answer, and a speed-limit answer without a '
                                'trained bank, is withheld ("no sign").',
                                low=0.0, high=1000.0)
    kth_law: float = setting(0.5, 'Exponent k of the kth-law nonlinearity applied to '
                             'spectrum magnitudes (1 = linear).', low=0.0, high=1.0)
    noise_tradeoff: float = setting(0.9, 'Optimal trade-off between MACE (0) and noise '
                                    'tolerance (1) in filter synthesis.', low=0.0, high=1.0)
    class_field_radius: float = setting(0.6, 'Classification looks only inside this '
                                        'fraction of the sign radius (the digits).',
                                        low=0.1, high=1.5)
    min_sign_radius_px: float = setting(5.0, 'Candidates with a smaller radius are answered '
                                        '"no sign", pixels.', low=1.0, high=200.0)
    magnify_margin: float = setting(1.1, 'Signs smaller than the smallest filters are '
                                    'magnified to this factor times its radius.',
                                    low=1.0, high=2.0)
    min_radius_px: float = setting(16.0, 'Smallest sign radius of the filter banks, pixels '
                                   '(smaller signs are magnified to it).',
                                   low=3.0, high=200.0)
    max_radius_px: float = setting(48.0, 'Largest sign radius of the filter banks, pixels.',
                                   low=4.0, high=400.0)
    radius_step: float = setting(1.12, 'Ratio between the radii of consecutive filter '
                                 'sizes.', low=1.02, high=2.0)
    canvas_margin: float = setting(0.15, 'Gray template border around the sign, as a '
                                   'fraction of its diameter on each side.', low=0.0,
                                   high=1.0)
    detection_psr_threshold: float = setting(4.0, 'Below this PSR of the best detection '
                                             'filter the candidate is answered "no sign" '
                                             'without running the classification filters '
                                             '(skips ~40% of background candidates on GTSDB, '
                                             'loses ~0.2% of real signs).', low=0.0,
                                             high=1000.0)
    crop_detection_psr_threshold: float = setting(
        2.5, 'The same gate for crops (classify_crop), which frame a sign, with a trained '
        'second opinion: signs whose ring the detection filters find weakly (backlit, dark) '
        'are still read, where the answer\'s PSR reaches psr_threshold (on gtsrb-dev 14 more '
        'limit crops read right, none wrong).',
        low=0.0, high=1000.0)
    crop_rendered_only_min_score: float = setting(
        0.0, 'Crops (classify_crop), which frame a sign: where the second opinion\'s best '
        'label is the correlation\'s leading limit but one it learned from renderings only '
        '(40 and 140 km/h with gtsrb-dev), the least score of that label for the answer to '
        'stand (the lower of this and the frames\' floor, which keeps clutter out). Leaving '
        'one value out of gtsrb-dev, 0.0 instead of the frames\' 0.3 read 60s right 0.860 '
        'instead of 0.806, 80s 0.866 instead of 0.844, none more wrong.',
        low=-1.0, high=1.0)
    frame_value_without_crops_min_psr: float = setting(
        10.0, 'Frames (not crops): the least correlation PSR for answering a limit the bank '
        'has no real crops of (known from composites of real digits or renderings only: 5, '
        '10, 40, 90, 110, 130, 140 km/h with gtsrb-dev); on weaker peaks clutter and other '
        'signs read as 5 or 40 (gtsdb-dev, 5 folds by scene: 5 of the 9 false limits in 466 '
        'frames, every one under PSR 9.5, went; no limit sign fewer recognized).',
        low=0.0, high=1000.0)
    frame_second_opinion_psr_threshold: float = setting(
        5.5, 'Frames (not crops): second_opinion_psr_threshold for a candidate of a frame, '
        'the PSR below which its answer is "no sign" (below psr_threshold the second '
        'opinion must still lead by second_opinion_low_psr_lead, and the other frame rules '
        'hold). Small far signs peak weakly (gtsdb-dev, 5 folds by scene, re-decided on '
        'recorded looks: 5.5 instead of 6 recognized 2 more of 284 limit signs, radii 5 and 8 px, '
        'the same 2 false limits in 466 frames).', low=0.0, high=1000.0)
    frame_overrule_min_psr: float = setting(
        8.0, 'Frames (not crops): the least correlation PSR for the second opinion to answer '
        "a limit other than the correlation's leading label; on weaker peaks that answer is "
        'withheld (gtsdb-dev, 5 folds by scene, re-decided on recorded looks: 3 of the 5 '
        'false limits in 466 frames went, each a limit the model read in clutter or in '
        'another round sign under a leader of PSR 6.3-7.8; no limit sign fewer '
        'recognized).', low=0.0, high=1000.0)
    max_cut_fraction: float = setting(0.2, 'A sign whose disc reaches beyond the frame '
                                      'border by more than this fraction of its radius is '
                                      'answered "no sign": its digits are cut off.',
                                      low=0.0, high=2.0)
    candidate_radius_scale: float = setting(1.28, 'Candidate radii are multiplied by this '
                                            'before the size search: the radial-symmetry '
                                            'detector reports about 0.77-0.78 of the '
                                            'outer radius (GTSDB, median, with both '
                                            'polarities voting; about 0.70 with '
                                            'bright_inside, which used 1.33).',
                                            low=0.2, high=5.0)
    size_search_ratio: float = setting(1.3, 'Detection filters searched: radii within this '
                                       'factor of the candidate radius.', low=1.0, high=4.0)
    larger_size_retry_factor: float = setting(
        1.7, 'A candidate of at least larger_size_retry_min_radius_px answered "no sign" is '
        'classified again at this factor times its radius: on large signs the '
        'radial-symmetry detector often reports the inner ring\'s or the digits\' radius, '
        'about half the outer one (1 = no retry).', low=1.0, high=4.0)
    larger_size_retry_min_radius_px: float = setting(
        9.0, 'Least candidate radius (detector pixels) for the larger-size retry.',
        low=0.0, high=1000.0)
    larger_size_retry_max_candidates: int = setting(
        2, 'At most this many candidates of a frame are retried at the larger size, the '
        'largest first (a bound on its time: clutter gives 2-4 per frame).', low=0, high=100)
    larger_size_retry_min_detection_psr: float = setting(
        6.0, 'Least PSR of the best detection filter at the larger size for the retry to '
        'run the classification filters (on gtsdb-dev the retried signs read there scored '
        '6.7-10, clutter mostly 4-5.6: the retry then costs little more than the detection '
        'filters).', low=0.0, high=1000.0)
    larger_size_retry_min_psr: float = setting(
        12.0, 'Least PSR of an answer of the larger-size retry (and of a crop\'s second '
        'looks: the padded and the framed retry): a second look needs clearer evidence '
        '(large round clutter matched a limit at PSR 9-11).',
        low=0.0, high=1000.0)
    position_search: float = setting(0.35, 'Peak search half-width around the candidate '
                                     'centre, as a fraction of its radius.', low=0.0,
                                     high=2.0)
    class_position_search: float = setting(0.1, 'Classification peak search half-width '
                                           'around the detected centre, fraction of the '
                                           'radius.', low=0.0, high=1.0)
    sidelobe_window: float = setting(0.65, 'PSR sidelobe window half-size, fraction of the '
                                     'radius.', low=0.1, high=3.0)
    sidelobe_exclude: float = setting(0.14, 'PSR excluded centre half-size, fraction of the '
                                      'radius.', low=0.0, high=1.0)
    class_score_top: int = setting(3, 'A class scores the mean PSR of its this many best '
                                   'filters (sizes x in-plane rotations).', low=1, high=15)
    class_neighbour_classes: int = setting(4, 'Leading classes refined: at the detected '
                                           'size every class is first correlated upright, '
                                           'then only this many leading classes with their '
                                           'rotated filters, and at the neighbouring sizes '
                                           'with all their filters.',
                                           low=1, high=30)
    class_size_neighbours: int = setting(1, 'Classification filters of this many sizes on '
                                         'each side of the detected size are also tried.',
                                         low=0, high=4)
    clahe_clip_limit: float = setting(0.0, 'CLAHE contrast clip limit applied to the ROI '
                                      'before detection (0 = no CLAHE).', low=0.0,
                                      high=40.0)
    clahe_tiles: int = setting(2, 'CLAHE tile grid (tiles per side) on the ROI.', low=1,
                               high=16)
    clahe_for_classification: bool = setting(False, 'Classify on the CLAHE-enhanced ROI '
                                             '(else CLAHE serves detection only).')
    crop_framing: str = setting('auto', 'How crops given to classify_crop frame the sign: '
                                '"margin" (GTSRB: 10% margin, at least 5 px), "tight" (the '
                                'box is the sign), "padded" (10% margin, no least margin) '
                                'or "auto" (any: margin and tight are tried, padded and '
                                'tight in a crop too small for margin\'s 5 px, the clearer '
                                'classification wins, and a small crop read as no sign is '
                                'tried once more as padded, and read where its PSR reaches '
                                'larger_size_retry_min_psr; as accurate as the right '
                                'framing on GTSRB crops, at twice the time per crop).',
                                choices=('auto', 'margin', 'tight', 'padded'))
    crop_framed_retry: bool = setting(
        True, 'A crop read as no sign is correlated once more with the detection filters held '
        'to its framing\'s centre and size (the free search sometimes settles on a larger '
        'size or another centre), and read where its PSR reaches larger_size_retry_min_psr.')
    crop_retry_size_search_ratio: float = setting(
        1.1, 'Framed retry: detection filters of radii within this factor of the framing\'s '
        'radius.', low=1.0, high=4.0)
    crop_retry_position_search: float = setting(
        0.12, 'Framed retry: peak search half-width around the crop\'s centre, fraction of '
        'the radius.', low=0.0, high=2.0)
    bank_file: str = setting('', 'Trained filter bank file (speed_sign_train build): real '
                             'examples in the composite filters and the second opinion. '
                             '"" = the bank shipped with the package, "none" = rendered '
                             'templates only.')
    cache_dir: str = setting('~/.cache/speed_sign_detector', 'Folder to cache the built '
                             'filter banks in, keyed by every parameter that shapes them '
                             '("" = build at every start, ~3-5 s).')

    def __post_init__(self) -> None:
        validate(self)
        if self.max_radius_px <= self.min_radius_px:
            raise ConfigError(f'classifier.max_radius_px ({self.max_radius_px}) must '
                              f'be larger than classifier.min_radius_px '
                              f'({self.min_radius_px})')


@dataclass(frozen=True)
class TrackerConfig:
    """Temporal integration (IVS 2011 III-C, DAGM 2010 section 4)."""

    window_frames: int = setting(10, 'Frames of the running window: votes older than '
                                 'this are forgotten, and a track unobserved this long '
                                 'expires.', low=1, high=100)
    window_s: float = setting(1.0, 'Seconds (message time) of the running window; the '
                              'shorter of window_frames and window_s applies.',
                              low=0.01, high=60.0)
    association_radius_factor: float = setting(1.0, 'A candidate joins a track when its '
                                               'centre lies within this many track radii.',
                                               low=0.1, high=10.0)
    unpredicted_association_radius_factor: float = setting(
        2.0, 'The same for a track observed once, whose motion is not known yet (at 10 Hz '
        'a near sign drifts more than its radius from one frame to the next).', low=0.1,
        high=10.0)
    growth_boost: float = setting(1.5, 'Factor on the vote of an observation that is larger '
                                  'than the oldest one in the window (approaching sign).',
                                  low=1.0, high=10.0)
    shrink_penalty: float = setting(0.5, 'Factor on the vote of an observation that is '
                                    'smaller than the oldest one in the window.',
                                    low=0.0, high=1.0)
    rotation_jump_deg: float = setting(8.0, 'In-plane rotation change counted as a jump.',
                                       low=0.0, high=90.0)
    rotation_penalty: float = setting(0.5, 'Factor on the vote when the rotation jumps.',
                                      low=0.0, high=1.0)
    recognition_threshold: float = setting(100.0, 'Evidence (sum of the weighted PSRs '
                                           'inside the window) at which a limit is '
                                           'recognized. A static artifact of PSR 9 reaches '
                                           'at most 10 x 9 = 90 in a 10-frame window.',
                                           low=0.0, high=1e6)

    def __post_init__(self) -> None:
        validate(self)


@dataclass(frozen=True)
class PipelineConfig:
    """Everything the pipeline needs: one config per stage plus the backend choice."""

    backend: str = setting(
        'auto', 'Detector backend: gl (OpenGL compute passes), cpu (OpenCV edges and '
        'vectorised voting on the CPU; the reference\'s votes to 0.2 %), numpy (the '
        'reference, slow), or auto: gl on a hardware GPU; on a software OpenGL renderer '
        '(Mesa llvmpipe) both gl and cpu detect the first 6 frames and the faster is kept '
        '(logged, and in /diagnostics as backend_choice); cpu when no OpenGL context can be '
        'made.', choices=('auto', 'gl', 'cpu', 'numpy'))
    classify: bool = setting(True, 'Run the classifier on the candidates (off: detection '
                             'only).')
    classifier_process: bool = setting(
        False, 'Run the classifier in a worker process of its own instead of in this one, '
        'so that detection and recognition do not take turns with one Python interpreter '
        '(its GIL). On an NVIDIA H100 host the node answered 26-29 fps of a 30 Hz '
        '1920x1080 camera with it against 23-25 without; on a 2-core host with the CPU '
        'detector, 18.5 against 14.1 fps of a 30 Hz 1280x720 camera. Costs a second process '
        '(its start-up and memory). With classifier_workers 0 (auto), false leaves the '
        'choice to the host size and true asks for worker processes on any host.')
    classifier_workers: int = setting(
        0, 'Frames classified at the same time, each by a worker process of its own '
        '(above 1 it needs classifier_process: true); frames are still tracked and '
        'published in the order they came. Each worker costs a process (its start-up and '
        'memory). 0 = auto, sized to the CPUs the node may use: max(1, min(3, (CPUs - 2) / '
        '2)) worker processes (2 CPUs left to the detector, the executor and DDS, half the '
        'rest to the host; on a 16-core NVIDIA H100 host a 30 Hz camera needed 2 workers at '
        '640x480 and 1920x1080, 60 Hz 1920x1080 needed 3), in this process (a thread '
        'beside the detector) on 1 CPU or without overlap_stages. 1 keeps the classifier '
        'in this process. The node logs the choice and reports it in /diagnostics '
        '(classifier); speed_sign_eval bag sizes it the same way, the fleet and the other '
        'offline tools take 0 as 1.',
        low=0, high=16)
    detector: DetectorConfig = field(default_factory=DetectorConfig)
    classifier: ClassifierConfig = field(default_factory=ClassifierConfig)
    tracker: TrackerConfig = field(default_factory=TrackerConfig)

    def __post_init__(self) -> None:
        validate(self)
        if self.classifier_workers > 1 and not self.classifier_process:
            raise ConfigError(f'classifier_workers ({self.classifier_workers}) '
                              'above 1 needs classifier_process: true (several classifiers '
                              'in one interpreter would take turns with its GIL)')


@dataclass(frozen=True)
class NodeOptions:
    """Options of the ROS node alone (the pipeline's are in :class:`PipelineConfig`).

    They share the node's parameter file with the pipeline's; the offline tools read
    that file too and ignore these.
    """

    publish_debug_image: bool = setting(True, 'Publish debug_image (drawn only while '
                                        'someone subscribes).')
    diagnostics_period_s: float = setting(1.0, 'Period of the /diagnostics status, '
                                          'seconds.', low=0.1, high=60.0)
    no_image_warning_s: float = setting(5.0, 'Warn when no image arrived for this many '
                                        'seconds.', low=0.5, high=3600.0)
    error_log_period_s: float = setting(5.0, 'Bad-input errors are logged at most once per '
                                        'this many seconds (the rest are counted).',
                                        low=0.0, high=3600.0)
    overlap_stages: bool = setting(True, 'Detect frame N+1 while frame N is recognized, on '
                                   'a second thread: on a multi-core machine frames go '
                                   'through at the pace of the slower stage instead of the '
                                   'sum of both, each a little later.')
    transport_loss_warning_share: float = setting(0.05, 'The status turns WARN, and the '
                                                  'log warns (every 10 s at most), when more '
                                                  'than this share of the frames sent since '
                                                  'the last diagnostics report was lost before '
                                                  'reaching the node (estimated from gaps in '
                                                  'the header stamps).', low=0.0, high=1.0)

    def __post_init__(self) -> None:
        validate(self)


SECTIONS: dict[str, type] = {
    'detector': DetectorConfig,
    'classifier': ClassifierConfig,
    'tracker': TrackerConfig,
}
