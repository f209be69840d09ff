"""Training a bank from labelled real crops (:func:`train_bank`).

1. The rendered-only classifier locates the sign in every crop (centre and radius, as
   it will at run time) and each sign is resampled to a canonical patch
   (:mod:`~speed_sign_detector.recognition.sign_features`).
2. Composite filters trained from real crops (:mod:`.filter_fitting`): one OT-MACH
   filter per label on the canonical patches of its crops, their degraded copies, the
   digit composites and the renderings; their PSR joins the rendered filters' in ranking
   the labels the second opinion chooses among. (Optionally, ``examples_per_class`` > 0:
   each class's patches grouped by k-means into a few mean images that join its
   renderings in the kth-law MACE filters at every size; measured worse, off by default.)
3. Second opinion: a model on gradient-orientation and pixel features, by default an
   ensemble of small networks (:mod:`.opinion_fitting`), or a ridge model
   (``model='linear'``), trained on the patches and on degraded copies of each crop
   (blur, JPEG, contrast loss, down-scaling), so that small, blurred and dim signs are
   seen in training.

Every limit value the package knows is learned from real pixels: values without real
crops (130, 140, ...) from composites of the real crops' digits
(:mod:`.digit_composites`), with renderings of the painted, LED and yellow-faced designs
beside them. Look-alike classes (round signs that are not limits) train the second
opinion's ``other_sign`` label; the end of all restrictions, which ends the limit too,
its ``end_of_limit`` label. Annotated scenes (GTSDB format, :mod:`.scene_examples`) add
the detector's candidates on real frames: whole-frame signs, and real background as
``no_sign``. Validation lives beside this module: k folds by track
(:mod:`.track_validation`), by scene (:mod:`.scene_validation`), and one value left out
at a time (:mod:`.value_holdout`).
"""
from __future__ import annotations

import dataclasses
import logging
import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from speed_sign_detector import __version__
from speed_sign_detector.config import ClassifierConfig, DetectorConfig
from speed_sign_detector.errors import TrainingDataError
from speed_sign_detector.image_files import UnreadableImageError, read_gray_image
from speed_sign_detector.labelled_crops import LabelledCrop, read_crop_folder
from speed_sign_detector.recognition.classifier import (
    Classification,
    Classifier,
    CorrelationEvidence,
)
from speed_sign_detector.recognition.sign_designs import design_label, design_training_crops
from speed_sign_detector.recognition.sign_features import aligned_patches, sign_features
from speed_sign_detector.recognition.templates import (
    ARCHED_SIX_GEOMETRY,
    END_OF_LIMIT_KINDS,
    GEOMETRY,
    LIMIT_VALUES_KMH,
    LOOKALIKE_KINDS,
    SignGeometry,
    gray_template,
)
from speed_sign_detector.recognition.trained_bank import NO_BANK_FILE, TrainedBank
from speed_sign_detector.training.degradation import degraded, jittered
from speed_sign_detector.training.digit_composites import digit_composites
from speed_sign_detector.training.filter_fitting import train_real_filters
from speed_sign_detector.training.opinion_fitting import fit_network_opinion, fit_second_opinion
from speed_sign_detector.training.scene_examples import (
    DetectedScene,
    SceneExamples,
    detect_scenes,
    read_scene_examples,
)
from speed_sign_detector.training.training_host import training_host

__all__ = ['MIN_LEAD_OF_MODEL', 'SECOND_OPINION_MODELS', 'LocatedCrops', 'TrainingConfig',
           'rendered_classifier', 'scene_examples_of',
           'locate_signs', 'rendered_training_crops', 'train_bank',
           'train_from_located']

_LOG = logging.getLogger(__name__)
#: Called with (done, total) as crops are processed.
ProgressCallback = Callable[[int, int], None]


#: The second opinion's forms :class:`TrainingConfig` takes.
SECOND_OPINION_MODELS: tuple[str, ...] = ('network', 'linear')
#: The least lead chosen for each form (5-fold gtsrb-dev): the network's ensemble scores
#: are averaged probabilities, the linear model's regression outputs.
MIN_LEAD_OF_MODEL: dict[str, float] = {'network': 0.6, 'linear': 0.2}


@dataclass(frozen=True)
class TrainingConfig:
    """How a bank is trained.

    Attributes:
        model: the second opinion's form: ``'network'`` (an ensemble of small networks,
            :mod:`.opinion_fitting`) or ``'linear'`` (ridge regression).
        ridge: Tikhonov regularisation of the linear second opinion (standardised
            features).
        hidden_units: hidden units of each network of the ensemble.
        epochs: training passes of each network.
        members: networks in the ensemble.
        candidates: the second opinion chooses among this many leading correlation labels.
        min_lead: its least score lead over its next best label (else no answer).
        augmented_copies: degraded copies of each training crop for the second opinion.
        examples_per_class: mean real images per class joining the composite filters
            (0 = renderings only; measured worse, see the README).
        rendered_per_kind: rendered, degraded crops of every sign kind the package draws
            (all limits, end-of-limit signs, look-alikes) added to the second opinion's
            training, so that it knows the values with no real examples.
        arched_six_per_kind: more rendered crops of each limit whose value has a 6 (60),
            drawn with the older lettering's arched 6 (:attr:`.templates.SignGeometry.arched_six`),
            which the real crops rarely show and the rest of the classifier reads as 8
            (like the other renderings, only where ``rendered_per_kind`` > 0).
        composites_per_value: composite crops of every speed-limit value the package
            knows (:data:`.templates.LIMIT_VALUES_KMH`), made from the real training crops'
            digits (:mod:`.digit_composites`), for the second opinion and the composite
            filters: values with no real crop (130, 110, ...) are then learned from real
            pixels too, and those whose digits all occur in real crops count as ones the
            second opinion may choose (0 = none: values without real crops are known from
            renderings only). 900 rather than 300: leaving one value out of gtsrb-dev
            (``speed_sign_train validate --leave-one-value-out --values V``), held-out 100s
            were read right 0.806 -> 0.875 and 120s 0.872 -> 0.881, no more read as another
            limit, the other values' crops as before (docs/recognition.md).
        design_per_kind: rendered crops of every limit in each sign design that painted
            signs lack (LED signs, read inverted as the classifier reads them, and
            yellow-faced signs) and of the end of all restrictions
            (:func:`.sign_designs.design_training_crops`), with the other renderings.
        scene_copies: degraded copies of each example cut from annotated scenes
            (:mod:`.scene_examples`).
        second_opinion: train the second opinion at all.
        real_filter_weight: weight of the composite filters trained from real crops
            (:mod:`.real_filters`) in ranking the labels the second opinion chooses among,
            against the rendered filters' 1 (0 = no real filters, the rendered ranking).
        real_filter_noise: their trade-off's white-noise weight, relative to the mean
            power of the examples.
        seed: seeds the augmentation, the k-means and the networks' training.
    """

    model: str = 'network'
    ridge: float = 30.0
    hidden_units: int = 256
    epochs: int = 12
    members: int = 3
    candidates: int = 4
    min_lead: float = MIN_LEAD_OF_MODEL['network']
    augmented_copies: int = 4
    examples_per_class: int = 0
    rendered_per_kind: int = 100
    arched_six_per_kind: int = 200
    composites_per_value: int = 900
    design_per_kind: int = 20
    scene_copies: int = 2
    second_opinion: bool = True
    real_filter_weight: float = 0.25
    real_filter_noise: float = 10.0
    seed: int = 0

    def __post_init__(self) -> None:
        if self.model not in SECOND_OPINION_MODELS:
            raise ValueError(f'unknown second-opinion model {self.model!r}; expected one of '
                             f'{", ".join(SECOND_OPINION_MODELS)}')
        for name in ('hidden_units', 'epochs', 'members', 'candidates'):
            if getattr(self, name) < 1:
                raise ValueError(f'{name} must be >= 1, got {getattr(self, name)}')
        for name in ('augmented_copies', 'rendered_per_kind', 'arched_six_per_kind',
                     'composites_per_value', 'design_per_kind',
                     'scene_copies', 'real_filter_weight', 'real_filter_noise'):
            if getattr(self, name) < 0:
                raise ValueError(f'{name} must be >= 0, got {getattr(self, name)}')



@dataclass(frozen=True)
class LocatedCrops:
    """Crops, with where the rendered-only classifier found each sign.

    Attributes:
        crops: the labelled crops.
        signs: (N, 3) float64 (x, y, radius) in crop pixels; NaN where none was found
            clearly enough to train on (:func:`locate_signs`).
        images: the (h, w) uint8 gray crops.
        evidence: what the rendered-only classifier measured in each crop
            (:meth:`Classifier.crop_evidence`), so that answers from the same filters need
            no second correlation.
    """

    crops: tuple[LabelledCrop, ...]
    signs: np.ndarray
    images: tuple[np.ndarray, ...]
    evidence: tuple[CorrelationEvidence | Classification, ...]

    def subset(self, mask: np.ndarray) -> LocatedCrops:
        """The crops where ``mask`` (N,) is true."""
        indices = np.flatnonzero(mask)
        return LocatedCrops(tuple(self.crops[i] for i in indices), self.signs[indices],
                            tuple(self.images[i] for i in indices),
                            tuple(self.evidence[i] for i in indices))


def read_crops(folders: Sequence[Path]) -> tuple[list[LabelledCrop], list[np.ndarray],
                                                 list[str]]:
    """Every crop of ``folders`` (labels.csv format) with its gray image.

    Returns:
        (crops, images, unreadable): unreadable images are skipped and listed as
        ``'path: reason'``.

    Raises:
        TrainingDataError: for a folder without a usable labels.csv, or no readable crop.
    """
    crops: list[LabelledCrop] = []
    images: list[np.ndarray] = []
    unreadable: list[str] = []
    for folder in folders:
        for crop in read_crop_folder(Path(folder)):
            try:  # decoded from the bytes, as the evaluation tools do: no OpenCV warning
                images.append(read_gray_image(crop.path))
                crops.append(crop)
            except UnreadableImageError as err:
                unreadable.append(f'{crop.path}: {err}')
    if not crops:
        raise TrainingDataError(f'no readable crop in {", ".join(str(f) for f in folders)}')
    return crops, images, unreadable


def locate_signs(classifier: Classifier, crops: Sequence[LabelledCrop],
                 images: Sequence[np.ndarray], progress: ProgressCallback | None = None
                 ) -> LocatedCrops:
    """Where ``classifier`` finds the sign in each crop (:meth:`Classifier.crop_evidence`).

    The evidence of every crop, as reading finds it, is kept for validation. The sign's
    position (``signs``, what training learns from) is located with the frames' gate
    ``detection_psr_threshold``: crops are read from the lower
    ``crop_detection_psr_threshold``, but a weakly found ring locates the sign less
    exactly, and training keeps to the clearly found ones."""
    signs = np.full((len(crops), 3), np.nan)
    found: list[CorrelationEvidence | Classification] = []
    training_gate = classifier.config.detection_psr_threshold
    for index, image in enumerate(images):
        evidence = classifier.crop_evidence(image)
        located = evidence
        if isinstance(evidence, CorrelationEvidence) and evidence.detection_psr < training_gate:
            # the clearest framing has a weak ring: the clearest of the others, if any
            located = classifier.crop_evidence(image, detection_psr_threshold=training_gate)
        if isinstance(located, CorrelationEvidence):
            signs[index] = (located.x_px, located.y_px, located.radius_px)
        found.append(evidence)
        if progress is not None:
            progress(index + 1, len(images))
    return LocatedCrops(tuple(crops), signs, tuple(images), tuple(found))


def _rendered_crop(kind: str, rng: np.random.Generator,
                   geometry: SignGeometry = GEOMETRY) -> np.ndarray:
    """One rendered crop (GTSRB framing) of ``kind`` at a random size (diameter 16-60
    px), angle and background, degraded."""
    diameter = float(rng.uniform(16.0, 60.0))
    margin = max(5.0, 0.1 * diameter)
    canvas = int(round(diameter + 2 * margin))
    crop = gray_template(kind, int(round(diameter)), canvas,
                         background=float(rng.uniform(40, 200)),
                         yaw_deg=float(rng.uniform(-25, 25)),
                         pitch_deg=float(rng.uniform(-10, 10)),
                         roll_deg=float(rng.uniform(-6, 6)), geometry=geometry)
    return degraded(crop, rng)


def rendered_training_crops(per_kind: int, rng: np.random.Generator,
                            arched_six_per_kind: int = 0
                            ) -> tuple[list[np.ndarray], list[str]]:
    """Rendered crops (GTSRB framing) of every limit, end-of-limit sign and look-alike the
    package draws, seen at random sizes (diameter 16-60 px), angles, backgrounds and
    degradations, ``per_kind`` of each; then ``arched_six_per_kind`` more of each limit
    whose value has a 6, drawn with the older lettering's arched 6
    (:data:`.templates.ARCHED_SIX_GEOMETRY`). Returns (gray crops, labels)."""
    kinds = ([str(v) for v in LIMIT_VALUES_KMH] + list(END_OF_LIMIT_KINDS)[::3]
             + list(LOOKALIKE_KINDS))
    crops: list[np.ndarray] = []
    labels: list[str] = []
    for kind in kinds:
        label = design_label(kind)
        for _ in range(per_kind):
            crops.append(_rendered_crop(kind, rng))
            labels.append(label)
    for kind in (str(v) for v in LIMIT_VALUES_KMH if '6' in str(v)):
        for _ in range(arched_six_per_kind):
            crops.append(_rendered_crop(kind, rng, ARCHED_SIX_GEOMETRY))
            labels.append(kind)
    return crops, labels


def _class_means(patches: np.ndarray, count: int, rng: np.random.Generator) -> np.ndarray:
    """``count`` k-means centres of (M, P, P) patches, each normalised to zero mean and
    unit variance first (so brightness does not decide the groups)."""
    flat = patches.reshape(len(patches), -1).astype(np.float64)
    flat = (flat - flat.mean(axis=1, keepdims=True)) / (flat.std(axis=1, keepdims=True) + 1e-6)
    count = min(count, len(flat))
    centres = flat[rng.choice(len(flat), count, replace=False)]
    for _ in range(15):
        nearest = np.argmin(((flat[:, None, :] - centres[None]) ** 2).sum(-1), axis=1)
        centres = np.stack([flat[nearest == k].mean(axis=0) if np.any(nearest == k)
                            else centres[k] for k in range(count)])
    return centres.reshape((count,) + patches.shape[1:]).astype(np.float32)


def train_from_located(located: LocatedCrops, config: TrainingConfig,
                       provenance: dict[str, Any] | None = None,
                       rendered: LocatedCrops | None = None,
                       scenes: SceneExamples | None = None) -> TrainedBank:
    """Train the bank's parts from crops located by the rendered-only classifier
    (``rendered``: located rendered crops, :func:`rendered_training_crops`, and
    ``scenes``: examples cut from annotated scenes, :mod:`.scene_examples`, both for the
    second opinion).

    Raises:
        TrainingDataError: when fewer than two labels have a located crop.
    """
    rng = np.random.default_rng(config.seed)
    found = np.isfinite(located.signs[:, 0])
    labels = [crop.label for crop in located.crops]
    patches = np.concatenate([aligned_patches(image, sign[None]) for image, sign, ok in zip(
        located.images, located.signs, found) if ok]) if found.any() else np.zeros((0, 1, 1))
    found_labels = [label for label, ok in zip(labels, found) if ok]
    if len(set(found_labels)) < 2:
        raise TrainingDataError('training needs located crops of at least two classes; '
                                f'found {sorted(set(found_labels))}')
    examples: dict[str, np.ndarray] = {}
    if config.examples_per_class > 0:
        for label in sorted(set(found_labels)):
            if label == 'other_sign':
                continue
            members = patches[[i for i, name in enumerate(found_labels) if name == label]]
            examples[label] = _class_means(members, config.examples_per_class, rng)
    opinion = None
    real_filters = None
    if config.second_opinion:
        # the patches both trained parts learn from: the crops, degraded copies of each
        # (jittered in position and size), and the located renderings
        patch_sets = [patches]
        patch_labels = list(found_labels)
        for _ in range(config.augmented_copies):
            patch_sets.append(np.concatenate(
                [aligned_patches(degraded(image, rng), jittered(sign, rng)[None])
                 for image, sign, ok in zip(located.images, located.signs, found) if ok]))
            patch_labels += found_labels
        composite_labels: set[str] = set()
        if config.composites_per_value > 0:
            composites = digit_composites(
                located.images, located.signs, labels,
                [str(value) for value in LIMIT_VALUES_KMH], config.composites_per_value, rng)
            if len(composites):
                # each composite once as made and once as a worse camera would see it
                patch_sets.append(np.concatenate([
                    aligned_patches(image, sign[None])
                    for image, sign in zip(composites.images, composites.signs)]))
                patch_sets.append(np.concatenate([
                    aligned_patches(degraded(image, rng), jittered(sign, rng)[None])
                    for image, sign in zip(composites.images, composites.signs)]))
                patch_labels += list(composites.labels) * 2
                # a value counts as learned from real pixels where all its digits were
                # real; one with a rendered digit (no real donor) stays a rendered class
                composite_labels = set(composites.labels) - {
                    label for label, rendered in zip(composites.labels,
                                                     composites.rendered_digits) if rendered}
        if rendered is not None:
            usable = np.isfinite(rendered.signs[:, 0])
            patch_sets.append(np.concatenate(
                [aligned_patches(image, sign[None]) for image, sign, ok in zip(
                    rendered.images, rendered.signs, usable) if ok]))
            patch_labels += [c.label for c, ok in zip(rendered.crops, usable) if ok]
        if config.real_filter_weight > 0:
            real_filters = train_real_filters(np.concatenate(patch_sets), patch_labels,
                                              config.real_filter_noise,
                                              weight=config.real_filter_weight)
        feature_rows = [sign_features(patch_set) for patch_set in patch_sets]
        feature_labels = list(patch_labels)
        crop_labels = set(found_labels)
        if scenes is not None and len(scenes):
            feature_rows.append(scenes.features)
            feature_labels += scenes.labels
            crop_labels |= set(scenes.labels)
        real_labels = crop_labels | composite_labels
        features = np.concatenate(feature_rows)
        # every label weighs the same in total (rare limits are not drowned)
        counts = Counter(feature_labels)
        weights = np.asarray([len(feature_labels) / (len(counts) * counts[label])
                              for label in feature_labels])
        if config.model == 'network':
            opinion = fit_network_opinion(features, feature_labels, config.hidden_units,
                                          config.epochs, config.members, config.seed, weights,
                                          real_labels=sorted(real_labels))
        else:
            opinion = fit_second_opinion(features, feature_labels, config.ridge, weights,
                                         real_labels=sorted(real_labels))
        # which real labels it saw real crops of (the rest: composites of real digits only)
        opinion = dataclasses.replace(opinion, crop_labels=tuple(
            label for label in opinion.labels if label in crop_labels))
    counts_by_label = Counter(labels)
    record = dict(provenance or {})
    record.update(crops=len(labels), located=int(found.sum()),
                  counts_per_class=dict(sorted(counts_by_label.items())),
                  scene_examples=scenes.counts() if scenes is not None else {},
                  training=dataclasses.asdict(config), package_version=__version__)
    return TrainedBank(opinion, config.candidates, config.min_lead, examples, record,
                       real_filters)


def rendered_classifier(config: ClassifierConfig) -> Classifier:
    """The classifier of ``config`` with the rendered filters alone (no trained bank)."""
    return Classifier(dataclasses.replace(config, bank_file=NO_BANK_FILE),
                      TrainedBank(None))


@dataclass(frozen=True)
class _RenderedCrop:
    """A rendered training crop's label (stands in for :class:`LabelledCrop`)."""

    label: str


def locate_rendered(classifier: Classifier, config: TrainingConfig) -> LocatedCrops | None:
    """The rendered training crops of ``config``, located by ``classifier``."""
    if config.rendered_per_kind <= 0 or not config.second_opinion:
        return None
    images, labels = rendered_training_crops(config.rendered_per_kind,
                                             np.random.default_rng(config.seed + 1),
                                             config.arched_six_per_kind)
    if config.design_per_kind > 0:
        design_images, design_labels = design_training_crops(
            config.design_per_kind, np.random.default_rng(config.seed + 3))
        images += design_images
        labels += design_labels
    crops = [_RenderedCrop(label) for label in labels]
    return locate_signs(classifier, crops, images)  # type: ignore[arg-type]


def scene_examples_of(folders: Sequence[Path], classifier: Classifier,
                    detector_config: DetectorConfig, config: TrainingConfig, backend: str
                    ) -> tuple[list[DetectedScene], SceneExamples | None]:
    """The detected scenes of ``folders`` and their examples (none without folders or a
    second opinion)."""
    if not folders or not config.second_opinion:
        return [], None
    scenes, unreadable = detect_scenes(folders, detector_config, backend)
    examples = read_scene_examples(scenes, classifier, config.scene_copies, config.seed + 2,
                                   unreadable)
    _LOG.info('%d examples from %d scenes: %s', len(examples), len(scenes),
              ', '.join(f'{label} {count}' for label, count in examples.counts().items()))
    return scenes, examples


def train_bank(folders: Sequence[Path], classifier_config: ClassifierConfig = ClassifierConfig(),
               config: TrainingConfig = TrainingConfig(),
               progress: ProgressCallback | None = None,
               scene_folders: Sequence[Path] = (),
               detector_config: DetectorConfig = DetectorConfig(),  # noqa: B008 (frozen)
               backend: str = 'auto') -> TrainedBank:
    """Train a bank from labelled crop folders (GTSRB ``labels.csv`` format) and annotated
    scene folders (GTSDB format, :mod:`.scene_examples`; their candidates come from the
    detector of ``detector_config`` on ``backend``).

    Raises:
        TrainingDataError: for unusable folders or too few located crops.
    """
    started = time.perf_counter()
    crops, images, unreadable = read_crops(folders)
    classifier = rendered_classifier(classifier_config)
    located = locate_signs(classifier, crops, images, progress)
    _, scenes = scene_examples_of(scene_folders, classifier, detector_config, config, backend)
    provenance = {'data_folders': [str(Path(f)) for f in folders],
                  'scene_folders': [str(Path(f)) for f in scene_folders],
                  'unreadable': unreadable + list(scenes.unreadable if scenes else ()),
                  'classifier': dataclasses.asdict(classifier_config),
                  'host': training_host()}
    bank = train_from_located(located, config, provenance, locate_rendered(classifier, config),
                              scenes)
    _LOG.info('trained on %d crops in %.1f s', len(crops), time.perf_counter() - started)
    return bank
