"""The Udacity numbers are defined once: every stage's default is the spec's value."""

from clonedrive.base import udacity_spec as spec
from clonedrive.cli import build_parser
from clonedrive.data.recipe import DEFAULT_CORRECTION
from clonedrive.data.recorder import RecordConfig
from clonedrive.drivers.policy import SpeedController
from clonedrive.manual.config import ManualConfig
from clonedrive.recipes.book import load_recipe_file
from clonedrive.sim.simulator import SimConfig
from clonedrive.udacity.client import ClientConfig
from clonedrive.world.vehicle import VehicleParams


def test_the_values_are_the_udacity_simulators():
    assert spec.IMAGE_SHAPE == (160, 320, 3)
    assert (spec.CONTROL_HZ, spec.MAX_WHEEL_ANGLE_DEG, spec.PORT) == (15.0, 25.0, 4567)
    assert (spec.JPEG_QUALITY, spec.SET_SPEED_MPH) == (75, 9.0)
    assert (spec.SPEED_KP, spec.SPEED_KI, spec.STEERING_CORRECTION) == (0.1, 0.002, 0.2)


def test_stage_defaults_come_from_the_spec():
    sim = SimConfig()
    assert (sim.image_height, sim.image_width, sim.control_hz) == (160, 320, spec.CONTROL_HZ)
    assert VehicleParams().max_wheel_angle_deg == spec.MAX_WHEEL_ANGLE_DEG
    assert RecordConfig().jpeg_quality == spec.JPEG_QUALITY
    assert ClientConfig().port == spec.PORT and ClientConfig().jpeg_quality == spec.JPEG_QUALITY
    session = ManualConfig()
    assert (session.server_port, session.jpeg_quality) == (spec.PORT, spec.JPEG_QUALITY)
    controller = SpeedController()
    assert (controller.set_speed_mph, controller.kp, controller.ki) == (9.0, 0.1, 0.002)
    assert DEFAULT_CORRECTION == spec.STEERING_CORRECTION
    writeup = load_recipe_file("writeup").data_recipe("data")
    assert {item.correction for item in writeup.recordings} == {spec.STEERING_CORRECTION}


def test_command_line_defaults_come_from_the_spec():
    parser = build_parser()
    drive = parser.parse_args(["drive", "model.keras"])
    assert (drive.port, drive.speed) == (spec.PORT, spec.SET_SPEED_MPH)
    assert parser.parse_args(["autonomous"]).port == spec.PORT
    assert parser.parse_args(["record", "--out", "x"]).jpeg_quality == spec.JPEG_QUALITY
