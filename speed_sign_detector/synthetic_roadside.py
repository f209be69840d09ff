"""The roadside objects and distractors of a synthetic drive (:mod:`.synthetic`): trees,
bushes, lamp posts with round globes and traffic mirrors along the road, a vehicle ahead
with a spare wheel and round tail lights, stickers on the windscreen. Where they are
(planned from the drive's random generator) and how they are drawn on a frame.

No ROS here; plain numpy and OpenCV drawing on (H, W, 3) float32 BGR frames.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from speed_sign_detector.synthetic_scenery import (
    ROAD_LEFT_M,
    ROAD_RIGHT_M,
    add_glow,
    fill_ellipse,
    fill_rect,
)

__all__ = ['LeadVehicle', 'Projection', 'RoadsideProp', 'Sticker', 'draw_lead_vehicle',
           'draw_props', 'draw_stickers', 'place_props', 'plan_lead_vehicle',
           'plan_stickers']

#: A frame's camera: world point (x, y, z), metres (Y down from the camera height) ->
#: (u px, v px, depth m), or ``None`` for a point behind the camera.
Projection = Callable[[float, float, float], tuple[float, float, float] | None]
#: The vehicle ahead: (start time s, end time s, shade 0..1).
LeadVehicle = tuple[float, float, float]
#: A windscreen sticker: (x px, y px, radius px, style).
Sticker = tuple[int, int, int, int]


@dataclass(frozen=True)
class RoadsideProp:
    """A roadside object: ``kind`` 'tree', 'lamp', 'mirror' or 'bush' at (``x_m``,
    ``z_m``) on the ground, metres; ``size_m`` its size (a lamp's globe radius, a mirror's
    radius), ``shade`` a brightness factor of its colours."""

    kind: str
    x_m: float
    z_m: float
    size_m: float
    shade: float


def place_props(rng: np.random.Generator, road_length_m: float) -> tuple[RoadsideProp, ...]:
    """Trees and bushes on both verges, lamp posts and traffic mirrors, along the road's
    first ``road_length_m`` metres and 200 m beyond."""
    road_end_m = road_length_m + 200.0
    props: list[RoadsideProp] = []
    z_m = 5.0
    while z_m < road_end_m:
        side = 1.0 if rng.uniform() < 0.5 else -1.0
        x_m = (ROAD_RIGHT_M + rng.uniform(3.0, 12.0) if side > 0
               else ROAD_LEFT_M - rng.uniform(2.5, 12.0))
        kind = 'tree' if rng.uniform() < 0.75 else 'bush'
        props.append(RoadsideProp(kind, float(x_m), float(z_m), float(rng.uniform(2.0, 5.0)),
                           float(rng.uniform(0.6, 1.2))))
        z_m += float(rng.uniform(4.0, 14.0))
    z_m = float(rng.uniform(10.0, 40.0))
    while z_m < road_end_m:
        props.append(RoadsideProp('lamp', ROAD_LEFT_M - 0.8 if rng.uniform() < 0.5
                           else ROAD_RIGHT_M + 1.6, z_m, 0.22, 1.0))
        z_m += float(rng.uniform(35.0, 60.0))
    z_m = float(rng.uniform(40.0, 120.0))
    while z_m < road_end_m:
        props.append(RoadsideProp('mirror', ROAD_LEFT_M - 1.0, z_m, 0.4, 1.0))
        z_m += float(rng.uniform(120.0, 250.0))
    return tuple(props)



def plan_lead_vehicle(rng: np.random.Generator, duration_s: float) -> LeadVehicle:
    """(start time s, end time s, shade) of the vehicle driving ahead in our lane during a
    drive of ``duration_s`` seconds."""
    start_s = float(rng.uniform(0.0, 0.4)) * duration_s
    return start_s, start_s + float(rng.uniform(0.3, 0.6)) * duration_s, float(
        rng.uniform(0.5, 1.0))



def plan_stickers(rng: np.random.Generator, width_px: int, height_px: int
                  ) -> tuple[Sticker, ...]:
    """Two windscreen stickers of a ``width_px`` x ``height_px`` frame: (x px, y px,
    radius px, style 0 (a parking sticker) or 1 (a dashboard dial))."""
    width, height = width_px, height_px
    return ((int(width * rng.uniform(0.78, 0.92)), int(height * rng.uniform(0.05, 0.15)),
             int(rng.uniform(12, 18)), 0),
            (int(width * rng.uniform(0.05, 0.2)), int(height * rng.uniform(0.85, 0.93)),
             int(rng.uniform(16, 24)), 1))



def draw_props(image: np.ndarray, props: Sequence[RoadsideProp], camera_z_m: float,
               project: Projection, focal_px: float, width_px: int, ground_y_m: float,
               night: float, emissive: bool) -> None:
    """Draw the props 1 to 150 m ahead of the camera, farthest first.

    Args:
        image: (H, W, 3) float32 BGR frame, drawn on in place.
        props: the drive's props.
        camera_z_m: the camera's position along the road, metres.
        project: the frame's camera: world (x, y, z) metres -> (u px, v px, depth m), or
            ``None`` behind the camera.
        focal_px: focal length, pixels.
        width_px: the frame's width, pixels.
        ground_y_m: the ground's Y (the camera height), metres.
        night: 0 (day) to 1 (night): how bright the lit lamps glow.
        emissive: draw the lit lamps' glow (after the scene is lit) instead of the props.
    """
    visible = [prop for prop in props if 1.0 < prop.z_m - camera_z_m < 150.0]
    for prop in sorted(visible, key=lambda prop: -(prop.z_m - camera_z_m)):
        base = project(prop.x_m, ground_y_m, prop.z_m)
        if base is None:
            continue
        u_px, v_px, depth_m = base
        scale = focal_px / depth_m
        if u_px < -400 or u_px > width_px + 400:
            continue
        if prop.kind == 'tree' and not emissive:
            trunk_w = max(1, int(0.25 * scale))
            crown_r = prop.size_m * 0.45 * scale
            top_v = v_px - prop.size_m * 1.3 * scale
            fill_rect(image, u_px - trunk_w / 2, top_v, u_px + trunk_w / 2, v_px,
                      (40 * prop.shade, 55 * prop.shade, 75 * prop.shade))
            fill_ellipse(image, u_px, top_v - 0.2 * crown_r, crown_r, 1.2 * crown_r,
                         (45 * prop.shade, 100 * prop.shade, 60 * prop.shade))
            fill_ellipse(image, u_px - 0.3 * crown_r, top_v - 0.5 * crown_r,
                         0.5 * crown_r, 0.6 * crown_r,
                         (60 * prop.shade, 125 * prop.shade, 80 * prop.shade))
        elif prop.kind == 'bush' and not emissive:
            radius = prop.size_m * 0.3 * scale
            fill_ellipse(image, u_px, v_px - 0.6 * radius, 1.4 * radius, 0.8 * radius,
                         (40 * prop.shade, 90 * prop.shade, 55 * prop.shade))
        elif prop.kind == 'lamp':
            top_v = v_px - 5.0 * scale
            globe_r = prop.size_m * scale
            if not emissive:
                fill_rect(image, u_px - 0.06 * scale, top_v, u_px + 0.06 * scale, v_px,
                          (105, 105, 110))
                fill_ellipse(image, u_px, top_v - globe_r, globe_r, globe_r,
                             (215, 220, 220))
            elif night > 0.0:
                add_glow(image, u_px, top_v - globe_r, globe_r, 200.0 * night)
        elif prop.kind == 'mirror' and not emissive:
            top_v = v_px - 2.4 * scale
            radius = prop.size_m * scale
            fill_rect(image, u_px - 0.05 * scale, top_v, u_px + 0.05 * scale, v_px,
                      (110, 110, 110))
            fill_ellipse(image, u_px, top_v, radius, radius, (20, 90, 230))
            fill_ellipse(image, u_px, top_v, 0.8 * radius, 0.8 * radius, (150, 140, 130))
            fill_ellipse(image, u_px - 0.2 * radius, top_v - 0.2 * radius,
                         0.4 * radius, 0.3 * radius, (200, 190, 180))



def draw_lead_vehicle(image: np.ndarray, vehicle: LeadVehicle | None, time_s: float,
                      camera_z_m: float, project: Projection, focal_px: float,
                      ground_y_m: float, night: float, emissive: bool) -> None:
    """Draw the vehicle ahead while it is there: closing in and falling back again, its
    spare wheel and tail lights (``emissive``: their glow at night). Arguments as
    :func:`draw_props`'s; ``time_s``: the frame's time, seconds."""
    if vehicle is None:
        return
    start_s, end_s, shade = vehicle
    if not start_s <= time_s <= end_s:
        return
    phase = (time_s - start_s) / max(end_s - start_s, 1e-6)
    gap_m = 14.0 + 40.0 * (1.0 - math.sin(math.pi * phase)) ** 2
    z_m = camera_z_m + gap_m
    base = project(0.0, ground_y_m, z_m)
    if base is None:
        return
    u_px, v_px, depth_m = base
    scale = focal_px / depth_m
    half_w, body_h = 0.95 * scale, 1.7 * scale
    wheel_v = v_px - 0.85 * scale
    light_r = 0.09 * scale
    lights = ((u_px - 0.75 * scale, v_px - 1.0 * scale), (u_px + 0.75 * scale,
                                                         v_px - 1.0 * scale))
    if not emissive:
        fill_rect(image, u_px - half_w, v_px - body_h, u_px + half_w, v_px - 0.25 * scale,
                  (150 * shade, 150 * shade, 140 * shade))
        fill_rect(image, u_px - half_w, v_px - 0.45 * scale, u_px + half_w, v_px,
                  (30, 30, 30))
        fill_ellipse(image, u_px, wheel_v, 0.36 * scale, 0.36 * scale, (25, 25, 25))
        fill_ellipse(image, u_px, wheel_v, 0.2 * scale, 0.2 * scale, (170, 170, 175))
        fill_ellipse(image, u_px, wheel_v, 0.05 * scale, 0.05 * scale, (60, 60, 60))
        for light_u, light_v in lights:
            fill_ellipse(image, light_u, light_v, light_r, light_r, (40, 40, 170))
    elif night > 0.0:
        for light_u, light_v in lights:
            add_glow(image, light_u, light_v, light_r, 180.0 * night, colour=(0.3, 0.3, 1.0))



def draw_stickers(image: np.ndarray, stickers: Sequence[Sticker]) -> None:
    """Draw the windscreen stickers (fixed in the image) on the (H, W, 3) float32 frame."""
    for x_px, y_px, radius, style in stickers:
        if style == 0:   # blue parking sticker with a white rim
            fill_ellipse(image, x_px, y_px, radius, radius, (230, 230, 230))
            fill_ellipse(image, x_px, y_px, 0.8 * radius, 0.8 * radius, (170, 90, 30))
        else:            # round dashboard dial
            fill_ellipse(image, x_px, y_px, radius, radius, (35, 35, 35))
            fill_ellipse(image, x_px, y_px, 0.85 * radius, 0.85 * radius, (90, 90, 90))
