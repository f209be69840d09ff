"""Per-stage times: in each FrameResult, in ``speed_sign_eval bag --json`` and in the
node's /diagnostics. The stages follow one another, so their times add up to at most
the frame's total (no timing thresholds: the machine is shared)."""
from __future__ import annotations

import contextlib
import io
import json
import math
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import cv2
import pytest
import rclpy
from rclpy.parameter import Parameter
from scene_helpers import approach_frames, textured_background
from sensor_msgs.msg import Image
from std_msgs.msg import Header

from speed_sign_detector.config import PipelineConfig
from speed_sign_detector.config_parameters import load_yaml
from speed_sign_detector.detection.detector import DETECTION_STAGES
from speed_sign_detector.pipeline import STAGE_TIMINGS, FrameResult, Pipeline
from speed_sign_detector.ros.messages import image_message
from speed_sign_detector.synthetic import DriveConfig, SyntheticDrive
from speed_sign_detector.tools import eval as eval_tool
from speed_sign_detector.tools.synth import write_drive
from speed_sign_detector.truth import write_truth

#: Rounding allowance when stage times are added up, milliseconds.
ROUNDING_MS = 1e-6
#: A ROS domain no other test module uses (see test/ros_spin.py's table).
NODE_DOMAIN_ID = 100
WAIT_S = 120.0


def assert_stage_times(timings_ms: dict[str, float]) -> None:
    """Every stage is there as a non-negative number, and the stages that follow one
    another (conversion, the detection's parts, classify, track) add up to at most the
    total; the detection's parts add up to at most the whole detection."""
    for key in (*STAGE_TIMINGS, 'detect', 'total'):
        value = timings_ms[key]
        assert isinstance(value, float) and math.isfinite(value) and value >= 0.0, (key,
                                                                                    value)
    assert sum(timings_ms[key] for key in STAGE_TIMINGS) <= timings_ms['total'] + ROUNDING_MS
    assert sum(timings_ms[key] for key in DETECTION_STAGES) <= timings_ms['detect'] \
        + ROUNDING_MS
    assert timings_ms['total'] == pytest.approx(
        timings_ms['conversion'] + timings_ms['detect'] + timings_ms['classify']
        + timings_ms['track'])


@pytest.mark.parametrize('backend', ['gl', 'numpy'])
def test_each_frame_reports_its_stages(backend: str, bank_config: Path) -> None:
    config = PipelineConfig(backend=backend, classifier=load_yaml(bank_config).classifier)
    results: list[FrameResult] = []
    with Pipeline(config) as pipeline:
        for index, (frame, *_rest) in enumerate(approach_frames('50', 4, 3)):
            gray = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
            results.append(pipeline.process(gray, stamp_s=index / 30, conversion_ms=1.5))
    for result in results:
        assert_stage_times(dict(result.timings_ms))
        assert result.timings_ms['conversion'] == 1.5
        assert result.timings_ms['gradients'] > 0.0 and result.timings_ms['voting'] > 0.0
    # candidates were classified in some frame: its classification took time
    assert any(result.detections and result.timings_ms['classify'] > 0.0
               for result in results)


def test_eval_bag_json_reports_the_stages(tmp_path: Path, bank_config: Path) -> None:
    """``speed_sign_eval bag --json``: median and mean per stage; the stages' means add
    up to at most the mean total."""
    frames = list(SyntheticDrive(DriveConfig(seed=1, duration_s=0.5, fps=20)))
    bag = tmp_path / 'drive'
    rows = write_drive(frames, bag, 'mcap', True)
    truth = tmp_path / 'truth.csv'
    write_truth(truth, rows)
    stdout, stderr = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        status = eval_tool.main(['bag', str(bag), '--truth', str(truth), '--json',
                                 '--config', str(bank_config)])
    assert status == 0, stderr.getvalue()
    summary = json.loads(stdout.getvalue().strip().splitlines()[-1])
    assert summary['frames'] == len(frames)
    for statistic in ('stage_ms_p50', 'stage_ms_mean'):
        for key in (*STAGE_TIMINGS, 'detect', 'total'):
            value = summary[statistic][key]
            assert isinstance(value, float) and value >= 0.0, (statistic, key, value)
    means = summary['stage_ms_mean']
    assert sum(means[key] for key in STAGE_TIMINGS) <= means['total'] + ROUNDING_MS
    assert means['conversion'] > 0.0  # the JPEG frames were decoded and timed
    # backend auto on llvmpipe: gl and cpu timed on the first 6 of the 10 frames, the
    # faster kept and named with both times
    if 'llvmpipe' in summary['backend_choice']:
        assert summary['backend'] in ('gl', 'cpu')
        assert summary['backend_choice'].startswith(f"auto: {summary['backend']}, ")
        assert 'ms per frame against' in summary['backend_choice']


@pytest.fixture()
def node(pytestconfig: pytest.Config) -> Iterator[Any]:
    """The node in a private context (no executor: the test hands it frames through its
    image subscription's callback, as the executor would)."""
    from speed_sign_detector.ros.node import SpeedSignDetectorNode

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=NODE_DOMAIN_ID)
    cache_dir = pytestconfig.cache.mkdir('speed_sign_filter_banks')
    built = SpeedSignDetectorNode(context=context, parameter_overrides=[
        Parameter('classifier.cache_dir', value=str(cache_dir))])
    try:
        yield built
    finally:
        built.destroy_node()
        rclpy.shutdown(context=context)


def test_node_diagnostics_report_the_stages(node: Any) -> None:
    """/diagnostics carries the median of every stage (``pipeline_<stage>_p50_ms``)."""
    subscription = next(item for item in node.subscriptions
                        if item.topic_name.endswith('/image'))
    message = image_message(textured_background(7), Header(), image_class=Image)
    message.header.stamp.sec = 1_700_000_000
    subscription.callback(message)
    deadline = time.monotonic() + WAIT_S
    values: dict[str, str] = {}
    while time.monotonic() < deadline:
        values = node.diagnostics_snapshot().values
        if int(values['frames_processed']) >= 1:
            break
        time.sleep(0.05)
    assert int(values['frames_processed']) >= 1, 'the node processed no frame'
    stages = {key: float(values[f'pipeline_{key}_p50_ms'])
              for key in (*STAGE_TIMINGS, 'detect', 'total')}
    assert all(value >= 0.0 for value in stages.values()), stages
    assert stages['conversion'] > 0.0  # the node converted the message and timed it
    assert values['backend_choice'].startswith('auto: ')  # how the backend was chosen
    # one frame: its medians are its own times, rounded to 0.1 ms in the diagnostics
    assert sum(stages[key] for key in STAGE_TIMINGS) <= stages['total'] \
        + 0.05 * (len(STAGE_TIMINGS) + 1)
