import numpy as np
import pytest

from clonedrive.sim.cameras import CameraRig
from clonedrive.sim.scene import RenderEngine, Scene
from clonedrive.sim.scenery import build_scenery, find_bridge
from clonedrive.world.catalog import load_track


def render_start(scene, width=80, height=40):
    track = scene.track
    x, y, z = track.point(5.0)
    with CameraRig(scene, ("center",), width, height) as rig:
        return rig.render(x, y, z, float(track.heading_at(5.0)))["center"]


@pytest.mark.parametrize("name", ["lake", "mountain", "gen:3"])
def test_scene_builds_and_renders_for_each_theme(name):
    with Scene(name) as scene:
        image = render_start(scene)
        assert scene.triangle_count > 1000
        assert image.shape == (40, 80, 3) and image.dtype == np.uint8
        assert image.std() > 10  # not a blank frame
        meshes = scene.scenery.meshes
        assert {"road", "ground", "tree"} <= set(meshes)
        if scene.theme == "lake":
            assert {"kerb", "water"} <= set(meshes)
            assert scene.scenery.bridge is not None
        else:
            assert "barrier" in meshes and "kerb" not in meshes


def test_the_lake_bridge_spans_the_long_straight_at_the_start():
    bridge = find_bridge(load_track("lake"))
    assert 15.0 < bridge.start_m < 45.0
    assert 80.0 <= bridge.length_m <= 110.0


def test_scenery_is_a_pure_function_of_the_track():
    track = load_track("gen:3")
    a = build_scenery(track)
    b = build_scenery(track)
    assert a.counts == b.counts
    for material, mesh in a.meshes.items():
        arrays_a, arrays_b = mesh.arrays(), b.meshes[material].arrays()
        for key in arrays_a:
            np.testing.assert_array_equal(arrays_a[key], arrays_b[key])


def test_two_scenes_one_after_the_other_in_one_process():
    track = load_track("lake")
    with Scene(track, scenery=False) as first:
        image_first = render_start(first)
    assert first.closed and first.engine.closed
    with Scene(track, scenery=False) as second:
        image_second = render_start(second)
    np.testing.assert_array_equal(image_first, image_second)


def test_close_is_idempotent_and_a_closed_scene_cannot_render():
    scene = Scene("lake", scenery=False)
    rig = CameraRig(scene, ("center",), 32, 16)
    scene.close()
    scene.close()
    assert rig.closed
    with pytest.raises(RuntimeError, match="closed"):
        rig.render(0.0, 0.0, 0.0, 0.0)
    with pytest.raises(RuntimeError, match="closed"):
        CameraRig(scene)


def test_engine_options_are_set_on_creation_and_removed_on_close():
    from panda3d.core import ConfigVariableString

    before = ConfigVariableString("load-display", "").get_value()
    engine = RenderEngine(options={"load-display": "p3tinydisplay"})
    assert ConfigVariableString("load-display", "").get_value() == "p3tinydisplay"
    engine.close()
    assert ConfigVariableString("load-display", "").get_value() == before
