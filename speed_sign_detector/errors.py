"""Error classes of the package: one per area, all deriving from SpeedSignError.

Messages say what was wrong and, where it helps, what to do about it.
"""
from __future__ import annotations


class SpeedSignError(Exception):
    """Base class of every error this package raises on purpose."""


class ConfigError(SpeedSignError, ValueError):
    """A configuration value is out of range or inconsistent with another."""


class DetectorError(SpeedSignError):
    """The detection stage could not run (for example, no OpenGL context)."""


class InvalidFrameError(DetectorError, ValueError):
    """A frame given to the detector is not a usable grayscale image."""


class ClassifierError(SpeedSignError):
    """The recognition stage could not run (for example, filter banks not buildable)."""


class ClassifierInputError(ClassifierError, ValueError):
    """An image given to the classifier is not a non-empty 2-D uint8 array."""


class ImageConversionError(SpeedSignError, ValueError):
    """An image message cannot be turned into a grayscale frame."""


class BagError(SpeedSignError):
    """A bag cannot be read or written (missing, truncated, no usable topic)."""


class TruthFileError(SpeedSignError, ValueError):
    """A ground-truth file is missing, malformed or inconsistent."""


class TrainingDataError(SpeedSignError, ValueError):
    """Labelled training crops cannot be read (missing, empty or malformed labels)."""


class BankFileError(ClassifierError):
    """A filter bank file cannot be read: missing, corrupt, or of another format version."""


class ClassifierProcessError(ClassifierError):
    """The classifier's worker process could not start, or exited while it was needed."""
