"""The classifier's placement sized to the host (``classifier_workers: 0``): the pure rule
over CPU counts and explicit settings, and its validation. No ROS, no processes started."""
from __future__ import annotations

import os

import pytest

from speed_sign_detector.classifier_placement import (
    ClassifierPlacement,
    choose_classifier_placement,
    place_classifier,
    usable_cpu_count,
)
from speed_sign_detector.config import PipelineConfig
from speed_sign_detector.errors import ConfigError


@pytest.mark.parametrize(('cpus', 'workers'), [
    (2, 1), (4, 1), (5, 1),                 # small hosts: one worker process...
    (6, 2), (7, 2),                         # ...(cpus - 2) // 2 of them...
    (8, 3), (16, 3), (128, 3),              # ...at most 3
])
def test_auto_sizes_worker_processes_to_the_host(cpus: int, workers: int) -> None:
    placement = choose_classifier_placement(cpus, 0, False)
    assert (placement.workers, placement.in_worker_processes) == (workers, True)
    assert placement.automatic and placement.cpus == cpus
    assert placement.reason == f'auto for {cpus} CPUs'


def test_auto_on_one_cpu_keeps_the_classifier_in_this_process() -> None:
    """A worker process could not run beside the detector: only the hand-over would
    be added."""
    placement = choose_classifier_placement(1, 0, False)
    assert (placement.workers, placement.in_worker_processes) == (1, False)
    assert placement.describe() == '1 classifier thread in this process (auto for 1 CPU)'


def test_the_16_core_host_gets_the_workers_its_measurements_needed() -> None:
    """On the 16-core H100 host 2 workers kept 30 Hz and 3 kept 60 Hz 1920x1080."""
    placement = choose_classifier_placement(16, 0, False)
    assert placement.describe() == '3 classifier worker processes (auto for 16 CPUs)'


@pytest.mark.parametrize('cpus', [2, 16])
def test_auto_without_overlapped_stages_keeps_the_classifier_in_this_process(
        cpus: int) -> None:
    placement = choose_classifier_placement(cpus, 0, False, overlap_stages=False)
    assert (placement.workers, placement.in_worker_processes) == (1, False)
    assert placement.describe() == (f'1 classifier thread in this process (auto for {cpus} '
                                    f'CPUs, stages not overlapped)')


@pytest.mark.parametrize(('cpus', 'workers'), [(1, 1), (2, 1), (4, 1), (6, 2), (16, 3)])
def test_classifier_process_true_is_honoured_with_auto_workers(cpus: int,
                                                               workers: int) -> None:
    placement = choose_classifier_placement(cpus, 0, True)
    assert (placement.workers, placement.in_worker_processes) == (workers, True)
    assert placement.reason == f'classifier_process true, auto for {cpus} CPUs'


@pytest.mark.parametrize(('cpus', 'workers', 'process'),
                         [(2, 1, False), (16, 1, False), (2, 1, True), (2, 2, True),
                          (16, 2, True), (16, 16, True)])
def test_an_explicit_worker_count_is_used_as_given(cpus: int, workers: int,
                                                   process: bool) -> None:
    placement = choose_classifier_placement(cpus, workers, process, overlap_stages=False)
    assert placement == ClassifierPlacement(cpus, workers, process, False,
                                            f'classifier_workers {workers}')
    config = PipelineConfig(classifier_process=process, classifier_workers=workers)
    assert place_classifier(config, cpus=cpus) == (config, placement)


def test_place_classifier_resolves_auto_into_the_config() -> None:
    config = PipelineConfig(classify=False)
    assert config.classifier_workers == 0  # the default is auto
    placed, placement = place_classifier(config, cpus=16)
    assert (placed.classifier_process, placed.classifier_workers) == (True, 3)
    assert placed.classify is False and placed.detector == config.detector
    placed, placement = place_classifier(config, cpus=2)
    assert (placed.classifier_process, placed.classifier_workers) == (True, 1)
    assert placement.describe() == '1 classifier worker process (auto for 2 CPUs)'
    placed, placement = place_classifier(config, overlap_stages=False, cpus=2)
    assert (placed.classifier_process, placed.classifier_workers) == (False, 1)


def test_usable_cpus_follow_the_affinity_mask() -> None:
    expected = (len(os.sched_getaffinity(0)) if hasattr(os, 'sched_getaffinity')
                else os.cpu_count())
    assert usable_cpu_count() == expected >= 1


def test_negative_values_are_rejected_with_a_reason() -> None:
    with pytest.raises(ConfigError, match=r'classifier_workers = -1 is below its minimum 0'):
        PipelineConfig(classifier_workers=-1)
    with pytest.raises(ValueError, match=r'classifier_workers must be >= 0 \(0 = auto\)'):
        choose_classifier_placement(4, -1, False)
    with pytest.raises(ValueError, match='cpus must be >= 1'):
        choose_classifier_placement(0, 0, False)
