"""The detector facade: validation, backend choice (GL, CPU or numpy), candidates.

``Detector(config, backend='auto')`` runs the radial-symmetry detector of IVS 2011 on
grayscale frames and returns up to ``config.max_candidates`` :class:`Candidate`, best
first. Backends: ``'gl'`` (moderngl compute passes), ``'cpu'`` (OpenCV edges and
vectorised stencil voting, :mod:`.gradients_cpu` and :mod:`.voting_cpu`), ``'numpy'``
(the reference the others are compared to in tests). ``'auto'`` keeps GL on a hardware
renderer; on a software one (llvmpipe) it times GL and CPU on the first frames and keeps
the faster (:mod:`.backend_trial`); with no OpenGL context it uses the CPU path (the
reason is logged and kept in ``fallback_reason``). ``backend_choice`` says which and why.

Working resolution: a frame wider than ``config.detection_width_px`` is scaled down to
that width (``cv2.INTER_AREA``) before voting, and only the band of rows between
``config.roi_top_fraction`` and ``config.roi_bottom_fraction`` is searched; candidates
are reported in the full-resolution frame's pixels (see :func:`working_frame`).
"""
from __future__ import annotations

import dataclasses
import logging
import time
from types import TracebackType
from typing import Self

import numpy as np

from speed_sign_detector.config import DetectorConfig
from speed_sign_detector.detection.area_scaling import scale_area
from speed_sign_detector.detection.backend_trial import BackendTrial, TrialDecision
from speed_sign_detector.detection.candidates import (
    BlockMaxima,
    Candidate,
    band_scores,
    block_maxima,
    score_normaliser,
    select_candidates,
)
from speed_sign_detector.detection.candidates_cpu import (
    packed_block_maxima,
    select_packed_candidates,
)
from speed_sign_detector.detection.gradients import validate_frame
from speed_sign_detector.detection.gradients_cpu import compute_edges_fast
from speed_sign_detector.detection.voting_cpu import CPUVoter
from speed_sign_detector.detection.voting_gl import SOFTWARE_RENDERERS
from speed_sign_detector.detection.voting_numpy import (
    RadiusBand,
    compute_edges,
    min_frame_size_px,
    plan_bands,
    vote_band,
    vote_images,
    vote_signs,
)
from speed_sign_detector.errors import ConfigError, DetectorError, InvalidFrameError

LOGGER = logging.getLogger(__name__)

BACKENDS = ('auto', 'gl', 'cpu', 'numpy')
#: ``Detector.renderer`` of the CPU path and of the numpy reference.
CPU_RENDERER = 'CPU (OpenCV and numpy)'
REFERENCE_RENDERER = 'numpy reference'

#: The detection stages :meth:`Detector.detect_with_stage_times` times, in order:
#: scaling (validation, region of interest, working resolution), gradients (gray scale,
#: pyramid, Sobel, edge lists), voting, candidates (block maxima, read-back, selection).
DETECTION_STAGES: tuple[str, ...] = ('scaling', 'gradients', 'voting', 'candidates')
#: The GL backend's own stages (``GLVoter.stage_ms``) in each of :data:`DETECTION_STAGES`.
_GL_STAGES: dict[str, tuple[str, ...]] = {
    'gradients': ('upload_pyramid', 'edges'), 'voting': ('vote',),
    'candidates': ('reduce', 'readback')}


@dataclasses.dataclass(frozen=True)
class WorkingFrame:
    """The part of a frame the detector votes on, at its working resolution.

    A working pixel ``(x, y)`` (pixel centres at whole coordinates) is the full-resolution
    point ``((x + 0.5) * scale_x - 0.5, top_row + (y + 0.5) * scale_y - 0.5)``: the area
    ``cv2.INTER_AREA`` averaged into it.

    Attributes:
        image: (h, w) uint8, the region of interest scaled to the working resolution.
        scale_x, scale_y: full-resolution pixels per working pixel (1 = not scaled).
        top_row: first full-resolution row of the region of interest.
    """

    image: np.ndarray
    scale_x: float
    scale_y: float
    top_row: int

    def to_full_resolution(self, candidate: Candidate) -> Candidate:
        """``candidate`` found on :attr:`image`, in full-resolution pixels (the radius
        scaled by the mean of the two scales)."""
        if self.scale_x == 1.0 and self.scale_y == 1.0 and self.top_row == 0:
            return candidate
        return dataclasses.replace(
            candidate,
            x_px=(candidate.x_px + 0.5) * self.scale_x - 0.5,
            y_px=self.top_row + (candidate.y_px + 0.5) * self.scale_y - 0.5,
            radius_px=candidate.radius_px * 0.5 * (self.scale_x + self.scale_y))


def working_frame(gray: np.ndarray, config: DetectorConfig, min_size_px: int = 1
                  ) -> WorkingFrame:
    """The region of interest of a validated (H, W) uint8 frame at the working resolution.

    Rows ``round(roi_top_fraction * H)`` to ``round(roi_bottom_fraction * H)`` (exclusive)
    are kept; a frame wider than ``detection_width_px`` (when not 0) is scaled down with
    ``cv2.INTER_AREA`` to that width and the band's height times the same factor.

    Raises:
        InvalidFrameError: when the scaled band is smaller than ``min_size_px`` on a side
            (naming the parameters that made it so).
    """
    height, width = gray.shape
    top = min(height - 1, max(0, round(config.roi_top_fraction * height)))
    bottom = max(top + 1, min(height, round(config.roi_bottom_fraction * height)))
    band = gray[top:bottom] if (top, bottom) != (0, height) else gray
    target = config.detection_width_px
    if 0 < target < width:
        scaled_width = target
        scaled_height = max(1, round(band.shape[0] * target / width))
        image = scale_area(band, (scaled_width, scaled_height))   # = cv2.INTER_AREA
    else:
        image = np.ascontiguousarray(band)
    if image.shape[0] < min_size_px or image.shape[1] < min_size_px:
        if image.shape == gray.shape:
            raise InvalidFrameError(f'frame {width}x{height} is smaller than the voting '
                                    f'window ({min_size_px} px on each side)')
        raise InvalidFrameError(
            f'frame {width}x{height} leaves {image.shape[1]}x{image.shape[0]} pixels to '
            f'search (rows {top} to {bottom} by detector.roi_top_fraction '
            f'{config.roi_top_fraction} and roi_bottom_fraction '
            f'{config.roi_bottom_fraction}, width by detector.detection_width_px {target}), '
            f'smaller than the voting window ({min_size_px} px on each side); widen the '
            f'region of interest or raise detector.detection_width_px')
    return WorkingFrame(image, band.shape[1] / image.shape[1], band.shape[0] / image.shape[0],
                        top)


def cpu_detector_advice(backend_name: str, renderer: str, config: DetectorConfig) -> str | None:
    """Advice for a detector that runs on the CPU with the settings that pay on a GPU.

    Both polarities voting and the smallest band voting at full resolution find more small
    and backlit signs, and on 2 CPU cores made the detector about twice as slow (see the
    README, "CPU-only hosts"). Returns None on a hardware GL renderer, or when neither
    setting is in use; else one line naming the parameters that trade those signs for
    frame rate.
    """
    on_cpu = backend_name in ('cpu', 'numpy') or is_software_renderer(renderer)
    costly = []
    if config.polarity == 'both':
        costly.append('detector.polarity:=bright_inside (and '
                      'classifier.candidate_radius_scale:=1.33)')
    if plan_bands(config)[0].target_level == 0:  # the smallest band at full resolution
        costly.append('detector.vote_pixels_per_radius:=1.75')
    if not on_cpu or not costly:
        return None
    return (f'the detector runs on the CPU ({renderer}); its settings favour small and '
            f'backlit signs over frame rate. Where the frame rate matters more: '
            f'{"; ".join(costly)} (README, "CPU-only hosts")')


def is_software_renderer(renderer: str) -> bool:
    """True when a GL_RENDERER string names a renderer that runs on the CPU."""
    return any(name in renderer.lower() for name in SOFTWARE_RENDERERS)


class Detector:
    """Radial-symmetry sign detector on one backend.

    Args:
        config: detector settings.
        backend: ``'gl'`` (moderngl, headless EGL), ``'cpu'`` (vectorised CPU path),
            ``'numpy'`` (reference) or ``'auto'`` (see the module text).

    Attributes:
        backend_name: ``'gl'``, ``'cpu'`` or ``'numpy'``: the backend in use (while an
            ``'auto'`` trial runs, ``'gl'``, whose candidates are returned).
        renderer: the GL_RENDERER string (also when ``'auto'`` kept the CPU path after
            timing it against a software renderer: the host's renderer stays named),
            :data:`CPU_RENDERER` (``'cpu'``, or no GL context) or
            :data:`REFERENCE_RENDERER`.
        vote_method: how votes are added: ``'raster'`` or ``'scatter'`` (GL),
            ``'stencil'`` (CPU), ``'numpy'``.
        fallback_reason: why ``'auto'`` could not use GL, else None.
        backend_choice: one line saying how the backend was chosen (with both times
            once an ``'auto'`` trial has decided).
        trial_decision: the decision of the ``'auto'`` trial, None before or without one.

    Raises:
        ConfigError: unknown backend name.
        DetectorError: ``backend='gl'`` and no GL context can be created.

    The GL context is created here and must be used from this thread only; call
    :meth:`close` (or use ``with``) to release it.
    """

    def __init__(self, config: DetectorConfig = DetectorConfig(),  # noqa: B008 (frozen)
                 backend: str = 'auto') -> None:
        if backend not in BACKENDS:
            raise ConfigError(f'unknown detector backend {backend!r}; use one of '
                              f'{", ".join(BACKENDS)}')
        self.config = config
        self.bands: tuple[RadiusBand, ...] = plan_bands(config)
        self.min_size_px = min_frame_size_px(config)
        self.score_normalisers: tuple[float, ...] = tuple(
            score_normaliser(len(vote_signs(config, band))) for band in self.bands)
        self.fallback_reason: str | None = None
        self.trial_decision: TrialDecision | None = None
        self._gl = None
        self._cpu: CPUVoter | None = None
        self._trial: BackendTrial | None = None
        if backend in ('auto', 'gl'):
            try:
                from speed_sign_detector.detection.voting_gl import GLVoter

                self._gl = GLVoter(config)
            except (DetectorError, ImportError) as err:
                if backend == 'gl':
                    if isinstance(err, DetectorError):
                        raise
                    raise DetectorError(f'GL backend unavailable: {err}') from err
                self.fallback_reason = str(err)
                LOGGER.warning('GL detector unavailable (%s); using the CPU path',
                               self.fallback_reason)
        software_gl = self._gl is not None and is_software_renderer(self._gl.renderer)
        if backend == 'cpu' or (backend == 'auto' and (self._gl is None or software_gl)):
            self._cpu = CPUVoter(config)
        if self._gl is not None:
            self._gl.profile_stages(True)  # per-stage times (a glFinish between stages)
            self._use('gl')
            self.backend_choice = (f'asked for gl ({self._gl.renderer})' if backend == 'gl'
                                   else f'auto: gl on a hardware renderer ({self.renderer})')
            if self._cpu is not None:
                self._trial = BackendTrial(self._gl.renderer)
                self.backend_choice = (f'auto: timing gl and cpu on the first frames '
                                       f'({self.renderer} is a software renderer)')
        elif self._cpu is not None:
            self._use('cpu')
            self.backend_choice = ('asked for cpu' if backend == 'cpu' else
                                   f'auto: cpu, GL unavailable ({self.fallback_reason})')
        else:
            self._use('numpy')
            self.backend_choice = 'asked for numpy (the reference)'
        LOGGER.info('detector backend: %s (%s), %s voting; %s', self.backend_name,
                    self.renderer, self.vote_method, self.backend_choice)
        self._closed = False

    def _use(self, backend_name: str) -> None:
        """Set the attributes that describe the backend in use."""
        self.backend_name = backend_name
        if backend_name == 'gl':
            self.renderer, self.vote_method = self._gl.renderer, self._gl.vote_method
        elif backend_name == 'cpu':
            self.vote_method = 'stencil'
            if self.trial_decision is None:   # else the software renderer it was timed on
                self.renderer = CPU_RENDERER
        else:
            self.renderer, self.vote_method = REFERENCE_RENDERER, 'numpy'

    def detect(self, gray: np.ndarray) -> tuple[Candidate, ...]:
        """Candidates of one (H, W) uint8 frame, best first (at most max_candidates).

        The frame's region of interest is searched at the working resolution (see
        :func:`working_frame`); the candidates' ``x_px``, ``y_px`` and ``radius_px`` are
        full-resolution pixels of ``gray``. ``radius_px`` is the voting radius (harmonic
        mean voting distance) divided by ``config.voting_edge_radius_ratio`` (see
        :class:`Candidate`).

        Raises:
            InvalidFrameError (a ValueError): unusable frame.
            DetectorError: the detector is closed.
        """
        return self.detect_with_stage_times(gray)[0]

    def detect_with_stage_times(self, gray: np.ndarray
                                ) -> tuple[tuple[Candidate, ...], dict[str, float]]:
        """:meth:`detect`, and the milliseconds each of :data:`DETECTION_STAGES` took.

        With the GL backend each stage ends with a wait for the driver (glFinish), so
        that its time is its own.

        Raises:
            InvalidFrameError (a ValueError): unusable frame.
            DetectorError: the detector is closed.
        """
        started = time.perf_counter()
        if self._closed:
            raise DetectorError('the detector has been closed')
        working = working_frame(validate_frame(gray, 1), self.config, self.min_size_px)
        scaled = time.perf_counter()
        if self._trial is not None:
            found, stage_ms = self._detect_on_trial(working)
        else:
            found, stage_ms = self._detect_on(self.backend_name, working)
        return found, {'scaling': (scaled - started) * 1e3, **stage_ms}

    def _detect_on(self, backend_name: str, working: WorkingFrame
                   ) -> tuple[tuple[Candidate, ...], dict[str, float]]:
        """Candidates of a working frame on one backend, in full-resolution pixels, and
        the milliseconds of its gradients, voting and candidates stages."""
        started = time.perf_counter()
        stage_ms: dict[str, float] = {}
        if backend_name == 'gl':
            self._gl.profile_stages(True)   # forget the last frame's times
            maxima = self._gl.block_maxima(working.image)
            gl_ms = self._gl.stage_ms or {}
            for stage, parts in _GL_STAGES.items():
                stage_ms[stage] = sum(gl_ms.get(part, 0.0) for part in parts)
            voted = time.perf_counter()
        else:
            frame_size = (working.image.shape[1], working.image.shape[0])
            if backend_name == 'cpu':
                edges = compute_edges_fast(working.image, self.config)
                edged = time.perf_counter()
                packed = self._cpu.packed_votes(edges, frame_size)
                voted = time.perf_counter()
                candidates = select_packed_candidates(
                    packed, self._cpu.stencils, working.image.shape,
                    self.config.block_size_px, self.score_normalisers,
                    self.config.max_candidates, self.config.min_score,
                    self.config.suppression_factor, self.config.enclosing_ring_ratio)
            else:
                edges = compute_edges(working.image, self.config)
                edged = time.perf_counter()
                tent = self.config.vote_profile == 'tent'
                votes = [vote_band(edges[band.level], band, vote_signs(self.config, band),
                                   frame_size, tent) for band in self.bands]
                voted = time.perf_counter()
                maxima = block_maxima(votes, self.bands, working.image.shape,
                                      self.config.block_size_px, self.score_normalisers)
            stage_ms['gradients'] = (edged - started) * 1e3
            stage_ms['voting'] = (voted - edged) * 1e3
            stage_ms['candidates'] = 0.0
        if backend_name != 'cpu':
            candidates = select_candidates(maxima, self.config.max_candidates,
                                           self.config.min_score,
                                           self.config.suppression_factor,
                                           self.config.enclosing_ring_ratio)
        ratio = self.config.voting_edge_radius_ratio
        found = tuple(working.to_full_resolution(
            dataclasses.replace(candidate, radius_px=candidate.radius_px / ratio))
            for candidate in candidates)
        stage_ms['candidates'] += (time.perf_counter() - voted) * 1e3
        return found, stage_ms

    def _detect_on_trial(self, working: WorkingFrame
                         ) -> tuple[tuple[Candidate, ...], dict[str, float]]:
        """Detect with both GL and CPU (see :mod:`.backend_trial`), return GL's result;
        once the trial decides, keep the faster (the GL context is released when the CPU
        path wins)."""
        results: dict[str, tuple[tuple[Candidate, ...], dict[str, float]]] = {}
        times_ms: dict[str, float] = {}
        for backend_name in self._trial.order():
            started = time.perf_counter()
            results[backend_name] = self._detect_on(backend_name, working)
            times_ms[backend_name] = (time.perf_counter() - started) * 1e3
        decision = self._trial.record(times_ms)
        if decision is not None:
            self._trial = None
            self.trial_decision = decision
            self.backend_choice = decision.describe()
            if decision.backend == 'cpu':
                self._gl.close()
                self._gl = None
            else:
                self._cpu.close()
                self._cpu = None
            self._use(decision.backend)
            LOGGER.info('detector backend chosen: %s', self.backend_choice)
        return results['gl']

    def block_maxima(self, gray: np.ndarray) -> BlockMaxima:
        """The per-block best vote pixels of a frame as given (before top-N selection;
        radii are voting radii; no working resolution or region of interest)."""
        frame = self._check(gray)
        if self._gl is not None:
            return self._gl.block_maxima(frame)
        if self._cpu is not None:
            packed = self._cpu.packed_votes(compute_edges_fast(frame, self.config),
                                            (frame.shape[1], frame.shape[0]))
            return packed_block_maxima(packed, self._cpu.stencils, frame.shape,
                                       self.config.block_size_px, self.score_normalisers)
        return block_maxima(vote_images(frame, self.config), self.bands, frame.shape,
                            self.config.block_size_px, self.score_normalisers)

    def vote_images(self, gray: np.ndarray) -> list[np.ndarray]:
        """Vote image of every radius band of the frame as given (for tests and pictures;
        no working resolution or region of interest).

        Returns:
            one (H_level, W_level, CHANNELS) float32 array per band of ``self.bands``:
            channels ``(sum w, count)`` with ``w = 1 / distance`` (see
            :mod:`.voting_numpy`). Band ``b`` is at pyramid level ``self.bands[b].level``.
        """
        frame = self._check(gray)
        if self._gl is not None:
            return self._gl.vote_images(frame)
        return self._cpu_vote_images(frame)

    def _cpu_vote_images(self, frame: np.ndarray) -> list[np.ndarray]:
        """Vote images of the CPU path, or of the reference when it is the backend."""
        if self._cpu is not None:
            return self._cpu.vote_images(compute_edges_fast(frame, self.config),
                                         (frame.shape[1], frame.shape[0]))
        return vote_images(frame, self.config)

    def score_map(self, gray: np.ndarray) -> np.ndarray:
        """Full-resolution picture of the votes: (H, W) float32, best band score per pixel.

        Each band's score image (about the fraction of a complete circle that voted,
        see :func:`.candidates.band_scores`) is enlarged to the frame size (each vote pixel
        covers ``band.target_scale`` pixels) and the maximum over bands is kept. Meant for
        debug pictures and the demo; :meth:`detect` does not need it.
        """
        frame = self._check(gray)
        height, width = frame.shape
        combined = np.zeros((height, width), np.float32)
        for band, votes, normaliser in zip(self.bands, self.vote_images(frame),
                                           self.score_normalisers):
            score = band_scores(votes, normaliser)
            scale = band.target_scale
            enlarged = np.repeat(np.repeat(score, scale, axis=0), scale, axis=1)
            combined[:enlarged.shape[0], :enlarged.shape[1]] = np.maximum(
                combined[:enlarged.shape[0], :enlarged.shape[1]], enlarged[:height, :width])
        return combined

    def close(self) -> None:
        """Release the GL context and the CPU path's voting thread (idempotent)."""
        if self._gl is not None:
            self._gl.close()
        if self._cpu is not None:
            self._cpu.close()
        self._closed = True

    @property
    def closed(self) -> bool:
        """True after :meth:`close`."""
        return self._closed

    def __enter__(self) -> Self:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 traceback: TracebackType | None) -> None:
        self.close()

    def _check(self, gray: np.ndarray) -> np.ndarray:
        if self._closed:
            raise DetectorError('the detector has been closed')
        return validate_frame(gray, self.min_size_px)
