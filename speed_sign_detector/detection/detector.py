"""The detector facade: validation, backend choice (GL or numpy), candidates.

``Detector(config, backend='auto')`` runs the radial-symmetry detector of IVS 2011 on
grayscale frames and returns up to ``config.max_candidates`` :class:`Candidate`, best
first. ``backend='auto'`` uses the GL backend and falls back to the numpy reference
when no OpenGL context can be created (the reason is logged and kept in
``fallback_reason``).
"""
from __future__ import annotations

import logging
from types import TracebackType

import numpy as np

from speed_sign_detector.config import DetectorConfig
from speed_sign_detector.detection.candidates import (
    BlockMaxima, Candidate, block_maxima, score_normaliser, select_candidates)
from speed_sign_detector.detection.gradients import validate_frame
from speed_sign_detector.detection.voting_numpy import (
    RadiusBand, min_frame_size_px, plan_bands, vote_images, vote_signs)
from speed_sign_detector.errors import ConfigError, DetectorError

LOGGER = logging.getLogger(__name__)

BACKENDS = ('auto', 'gl', 'numpy')


class Detector:
    """Radial-symmetry sign detector on one backend.

    Args:
        config: detector settings.
        backend: ``'gl'`` (moderngl, headless EGL), ``'numpy'`` (reference) or ``'auto'``
            (GL, numpy when no GL context can be created).

    Attributes:
        backend_name: ``'gl'`` or ``'numpy'``.
        renderer: the GL_RENDERER string, or ``'numpy reference'``.
        fallback_reason: why ``'auto'`` fell back to numpy, else None.

    Raises:
        ConfigError: unknown backend name.
        DetectorError: ``backend='gl'`` and no GL context can be created.

    The GL context is created here and must be used from this thread only; call
    :meth:`close` (or use ``with``) to release it.
    """

    def __init__(self, config: DetectorConfig = DetectorConfig(), backend: str = 'auto') -> None:
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
        else:
            self.backend_name = 'numpy'
            self.renderer = 'numpy reference'
        LOGGER.info('detector backend: %s (%s)', self.backend_name, self.renderer)
        self._closed = False

    def detect(self, gray: np.ndarray) -> tuple[Candidate, ...]:
        """Candidates of one (H, W) uint8 frame, best first (at most max_candidates).

        Raises:
            InvalidFrameError (a ValueError): unusable frame.
            DetectorError: the detector is closed.
        """
        maxima = self.block_maxima(gray)
        return select_candidates(maxima, self.config.max_candidates, self.config.min_score,
                                 self.config.suppression_factor)

    def block_maxima(self, gray: np.ndarray) -> BlockMaxima:
        """The per-block best vote pixels of a frame (before top-N selection)."""
        frame = self._check(gray)
        if self._gl is not None:
            return self._gl.block_maxima(frame)
        return block_maxima(vote_images(frame, self.config), self.bands, frame.shape,
                            self.config.block_size_px, self.score_normalisers)

    def vote_images(self, gray: np.ndarray) -> list[np.ndarray]:
        """Vote image of every radius band (for tests and pictures).

        Returns:
            one (H_level, W_level, CHANNELS) float32 array per band of ``self.bands``:
            channels ``(sum w, count)`` with ``w = 1 / distance`` (see :mod:`.voting_numpy`). Band ``b`` is at pyramid level ``self.bands[b].level``.
        """
        frame = self._check(gray)
        if self._gl is not None:
            return self._gl.vote_images(frame)
        return vote_images(frame, self.config)

    def close(self) -> None:
        """Release the GL context (idempotent)."""
        if self._gl is not None:
            self._gl.close()
        self._closed = True

    @property
    def closed(self) -> bool:
        """True after :meth:`close`."""
        return self._closed

    def __enter__(self) -> Detector:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 traceback: TracebackType | None) -> None:
        self.close()

    def _check(self, gray: np.ndarray) -> np.ndarray:
        if self._closed:
            raise DetectorError('the detector has been closed')
        return validate_frame(gray, self.min_size_px)
