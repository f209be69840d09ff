"""Where the node's classifier runs when ``classifier_workers`` is 0 (auto): sized to the host.

:func:`choose_classifier_placement` is the whole decision, a pure function of the CPU
count and the two parameters; :func:`place_classifier` applies it to a
:class:`~speed_sign_detector.config.PipelineConfig` (the node calls it before it builds
or reconfigures its pipeline). No ROS imports here.

The rule (auto, ``classifier_workers: 0``), for ``cpus`` the CPUs this process may use:

- stages not overlapped (``overlap_stages: false``): in this process. The worker
  classifies each frame after detecting it, so a process would only add the hand-over.
- one CPU: in this process (a worker process could not run beside the detector).
- two CPUs or more: ``max(1, min(3, (cpus - 2) // 2))`` worker processes. Two CPUs are
  left to the detector thread and to the executor and DDS, and half of the rest to
  whatever else the host runs; the cap, :data:`MAX_AUTO_WORKERS`, is what the
  measurements justify: on a 16-core NVIDIA H100 host the node kept a 30 Hz 640x480
  camera only with 2 worker processes (27-29 fps in-thread), 1920x1080 at 30 Hz with 2
  and at 60 Hz with 3. Small hosts get one: with the CPU detector (the choice on a
  software OpenGL renderer) detection and recognition in one interpreter take turns with
  its GIL, and on the 2-core development machine one worker process answered more frames
  than the recognition thread, measured in the same minutes (node at 1280x720 and 30 Hz:
  18.5 fps against 14.1; ``speed_sign_eval bag`` at 640x480: 26 against 19 fps).

``classifier_process: true`` is honoured: with auto workers it means worker processes on
any host, ``max(1, ...)`` of them. ``false`` is the default and leaves the choice to the
rule; to keep the classifier in this process on any host, set ``classifier_workers:
1``. An explicit ``classifier_workers`` (1 to 16) is used as given, as before.
"""
from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass

from speed_sign_detector.config import PipelineConfig

#: ``classifier_workers`` value meaning "size to the host".
AUTO_WORKERS = 0
#: CPUs auto leaves to the detector thread, the executor and DDS.
RESERVED_CPUS = 2
#: Most worker processes auto starts (3 kept a 60 Hz 1920x1080 camera on an H100 host).
MAX_AUTO_WORKERS = 3


@dataclass(frozen=True)
class ClassifierPlacement:
    """Where the classifier runs, and why.

    Attributes:
        cpus: CPUs this process may use, as seen when the choice was made.
        workers: classifiers reading frames at the same time (>= 1).
        in_worker_processes: True: ``workers`` processes of their own; False: one
            classifier in this process (a recognition thread beside the detector when
            the stages overlap).
        automatic: True when ``classifier_workers`` was 0 (auto).
        reason: what decided it, in a few words (``auto for 2 CPUs``).
    """

    cpus: int
    workers: int
    in_worker_processes: bool
    automatic: bool
    reason: str

    def describe(self) -> str:
        """One line for the log: ``2 classifier worker processes (auto for 16 CPUs)``,
        ``1 classifier thread in this process (auto for 2 CPUs)``."""
        where = (f'{self.workers} classifier worker process'
                 f'{"es" if self.workers > 1 else ""}' if self.in_worker_processes
                 else '1 classifier thread in this process')
        return f'{where} ({self.reason})'


def usable_cpu_count() -> int:
    """CPUs this process may run on: its affinity mask where the OS has one (a container
    or ``taskset`` limit), else ``os.cpu_count()``; at least 1."""
    if hasattr(os, 'sched_getaffinity'):
        return max(1, len(os.sched_getaffinity(0)))
    return max(1, os.cpu_count() or 1)


def choose_classifier_placement(cpus: int, classifier_workers: int,
                                classifier_process: bool, overlap_stages: bool = True
                                ) -> ClassifierPlacement:
    """The placement the parameters ask for on a host with ``cpus`` usable CPUs (the
    rule is in the module docstring).

    Args:
        cpus: usable CPUs (:func:`usable_cpu_count`), >= 1.
        classifier_workers: the parameter: 0 = auto, else the count to use as given.
        classifier_process: the parameter (True is honoured; False leaves auto free).
        overlap_stages: the node option; without overlap auto keeps the classifier here.

    Raises:
        ValueError: ``cpus`` below 1 or ``classifier_workers`` negative.
    """
    if cpus < 1:
        raise ValueError(f'cpus must be >= 1, got {cpus}')
    if classifier_workers < 0:
        raise ValueError(f'classifier_workers must be >= 0 (0 = auto), got '
                         f'{classifier_workers}')
    if classifier_workers != AUTO_WORKERS:
        return ClassifierPlacement(cpus, classifier_workers, classifier_process, False,
                                   f'classifier_workers {classifier_workers}')
    sized = min(MAX_AUTO_WORKERS, (cpus - RESERVED_CPUS) // 2)
    if classifier_process:
        return ClassifierPlacement(cpus, max(1, sized), True, True,
                                   f'classifier_process true, auto for {cpus} CPUs')
    if not overlap_stages:
        return ClassifierPlacement(cpus, 1, False, True,
                                   f'auto for {cpus} CPUs, stages not overlapped')
    if cpus == 1:
        return ClassifierPlacement(cpus, 1, False, True, 'auto for 1 CPU')
    return ClassifierPlacement(cpus, max(1, sized), True, True, f'auto for {cpus} CPUs')


def place_classifier(config: PipelineConfig, overlap_stages: bool = True,
                     cpus: int | None = None) -> tuple[PipelineConfig, ClassifierPlacement]:
    """``config`` with ``classifier_process`` and ``classifier_workers`` as
    :func:`choose_classifier_placement` decides for this host (``cpus`` defaults to
    :func:`usable_cpu_count`), and the placement itself. An explicit worker count
    leaves ``config`` as it is."""
    placement = choose_classifier_placement(
        usable_cpu_count() if cpus is None else cpus, config.classifier_workers,
        config.classifier_process, overlap_stages)
    if not placement.automatic:
        return config, placement
    return dataclasses.replace(config, classifier_process=placement.in_worker_processes,
                               classifier_workers=placement.workers), placement
