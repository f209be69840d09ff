"""The detector facade: validation, backend choice (GL or numpy), candidates.

``Detector(config, backend='auto')`` runs the radial-symmetry detector of IVS 2011 on
grayscale frames and returns up to ``config.max_candidates`` :class:`Candidate`, best
first. ``backend='auto'`` uses the GL backend and falls back to the numpy reference
when no OpenGL context can be created (the reason is logged and kept in
``fallback_reason``).
"""
from __future__ import annotations

import dataclasses
import logging
from types import TracebackType
from typing import Self

import numpy as np

from speed_sign_detector.config import DetectorConfig
from speed_sign_detector.detection.candidates import (
    BlockMaxima,
    Candidate,
    band_scores,
    block_maxima,
    score_normaliser,
    select_candidates,
)
from speed_sign_detector.detection.gradients import validate_frame
from speed_sign_detector.detection.voting_gl import SOFTWARE_RENDERERS
from speed_sign_detector.detection.voting_numpy import (
    RadiusBand,
    min_frame_size_px,
    plan_bands,
    vote_images,
    vote_signs,
)
from speed_sign_detector.errors import ConfigError, DetectorError

LOGGER = logging.getLogger(__name__)

BACKENDS = ('auto', 'gl', 'numpy')


def cpu_detector_advice(backend_name: str, renderer: str, config: DetectorConfig) -> str | None:
    """Advice for a detector that runs on the CPU with the settings that pay on a GPU.

    Both polarities voting and the smallest band voting at full resolution find more small
    and backlit signs, and on 2 CPU cores made the detector about twice as slow (see the
    README, "CPU-only hosts"). Returns None on a hardware GL renderer, or when neither
    setting is in use; else one line naming the parameters that trade those signs for
    frame rate.
    """
    on_cpu = backend_name == 'numpy' or any(name in renderer.lower()
                                            for name in SOFTWARE_RENDERERS)
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


class Detector:
    """Radial-symmetry sign detector on one backend.

    Args:
        config: detector settings.
        backend: ``'gl'`` (moderngl, headless EGL), ``'numpy'`` (reference) or ``'auto'``
            (GL, numpy when no GL context can be created).

    Attributes:
        backend_name: ``'gl'`` or ``'numpy'``.
        renderer: the GL_RENDERER string, or ``'numpy reference'``.
        vote_method: how votes are added: ``'raster'`` or ``'scatter'`` (GL), ``'numpy'``.
        fallback_reason: why ``'auto'`` fell back to numpy, else None.

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
        self._gl = None
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
                LOGGER.warning('GL detector unavailable (%s); using the numpy reference',
                               self.fallback_reason)
        if self._gl is not None:
            self.backend_name = 'gl'
            self.renderer = self._gl.renderer
            self.vote_method = self._gl.vote_method
        else:
            self.backend_name = 'numpy'
            self.renderer = 'numpy reference'
            self.vote_method = 'numpy'
        LOGGER.info('detector backend: %s (%s), %s voting', self.backend_name, self.renderer,
                    self.vote_method)
        self._closed = False

    def detect(self, gray: np.ndarray) -> tuple[Candidate, ...]:
        """Candidates of one (H, W) uint8 frame, best first (at most max_candidates).

        ``radius_px`` is the voting radius (harmonic mean voting distance) divided by
        ``config.voting_edge_radius_ratio`` (see :class:`Candidate`).

        Raises:
            InvalidFrameError (a ValueError): unusable frame.
            DetectorError: the detector is closed.
        """
        maxima = self.block_maxima(gray)
        candidates = select_candidates(maxima, self.config.max_candidates,
                                       self.config.min_score, self.config.suppression_factor)
        ratio = self.config.voting_edge_radius_ratio
        return tuple(dataclasses.replace(candidate, radius_px=candidate.radius_px / ratio)
                     for candidate in candidates)

    def block_maxima(self, gray: np.ndarray) -> BlockMaxima:
        """The per-block best vote pixels of a frame (before top-N selection; radii are
        voting radii)."""
        frame = self._check(gray)
        if self._gl is not None:
            return self._gl.block_maxima(frame)
        return block_maxima(vote_images(frame, self.config), self.bands, frame.shape,
                            self.config.block_size_px, self.score_normalisers)

    def vote_images(self, gray: np.ndarray) -> list[np.ndarray]:
        """Vote image of every radius band (for tests and pictures).

        Returns:
            one (H_level, W_level, CHANNELS) float32 array per band of ``self.bands``:
            channels ``(sum w, count)`` with ``w = 1 / distance`` (see
            :mod:`.voting_numpy`). Band ``b`` is at pyramid level ``self.bands[b].level``.
        """
        frame = self._check(gray)
        if self._gl is not None:
            return self._gl.vote_images(frame)
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
        """Release the GL context (idempotent)."""
        if self._gl is not None:
            self._gl.close()
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
