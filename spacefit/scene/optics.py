"""What the camera's values make together: the pixel pitch a field of view sets, the field of view and
the angle of one pixel a pinhole can render."""

from __future__ import annotations

import math
from typing import Any

from spacefit.errors import InputError, quote
from spacefit.scene.sections import MAX_FOV_DEG, CameraSettings, RenderSettings, SceneLike




# The smallest angle (rad) a pixel may subtend, pixel pitch over focal length: Mitsuba's ray
# directions are float32 (relative precision 6e-8), so narrower pixels get rays that repeat: a
# sphere's limb seen from 11 km rendered blocks of 2 to 3 equal pixels at 3e-7 rad and of about 10
# at 1e-7 rad, none at 1e-6 rad (about 16 float32 steps per pixel).
MIN_PIXEL_ANGLE_RAD = 1e-6


def fov_pitch_mm(camera: CameraSettings, render: RenderSettings) -> float:
    """The pixel pitch (mm) that gives ``camera.fov_deg`` across ``render.resolution``'s width."""
    return 2.0 * camera.focal_length_mm * math.tan(math.radians(camera.fov_deg) / 2.0) / render.resolution[0]


def check_pitch_with_fov(scene: SceneLike, pitch_mm: Any) -> None:
    """Raise :class:`InputError` if ``camera.pixel_pitch_mm`` was given (as ``pitch_mm``) while
    ``camera.fov_deg`` sets the field of view, and with it the pitch."""
    camera = scene.camera
    if camera.fov_deg > 0.0:
        raise InputError(f"`camera.pixel_pitch_mm` = {quote(pitch_mm)} was given while `camera.fov_deg` = {camera.fov_deg:g} sets "
                         f"the field of view, which makes the pitch {camera.pixel_pitch_mm:.6g} mm at {scene.render.resolution[0]} px: "
                         "give one of them (`camera.fov_deg` = 0 leaves the field to the pixel pitch).")


def check_optics(camera: CameraSettings, render: RenderSettings) -> None:
    """Check what the camera's values make together: the field of view along each image axis,
    ``2 atan(size * pitch / (2 focal length))``, at most :data:`MAX_FOV_DEG`, and the angle of one
    pixel, ``pitch / focal length``, at least :data:`MIN_PIXEL_ANGLE_RAD`."""
    keys = "`camera.focal_length_mm`, `camera.pixel_pitch_mm` and `render.resolution`"
    ratio = camera.pixel_pitch_mm / camera.focal_length_mm  # may over- or underflow: inf and 0 are refused below
    for axis, size in zip(("horizontal", "vertical"), render.resolution):
        fov = math.degrees(2.0 * math.atan(0.5 * size * ratio))
        if fov > MAX_FOV_DEG:
            raise InputError(f"{keys} give a {axis} field of view of {fov:.6g} deg ({size} px of {camera.pixel_pitch_mm:g} mm "
                             f"behind a {camera.focal_length_mm:g} mm lens); a pinhole camera renders at most {MAX_FOV_DEG:g} deg: "
                             "lengthen the focal length or use fewer or smaller pixels.")
    if not ratio >= MIN_PIXEL_ANGLE_RAD:
        raise InputError(f"`camera.pixel_pitch_mm` / `camera.focal_length_mm` = {camera.pixel_pitch_mm:g} / "
                         f"{camera.focal_length_mm:g} gives pixels of {ratio:.3g} rad; at least {MIN_PIXEL_ANGLE_RAD:g} rad "
                         "(float32 rays resolve no finer): shorten the focal length, or render nearer and rescale.")
