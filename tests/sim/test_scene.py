import numpy as np
import pytest

from clonedrive.sim.cameras import CameraRig
from clonedrive.sim.engine import RenderEngine
from clonedrive.sim.scene import Scene
from clonedrive.sim.scenery import build_scenery, find_bridge
from clonedrive.sim.scenery.site import WATER_BELOW_BRIDGE_M, WATER_BELOW_ROAD_M, water_level
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


def test_every_scene_of_a_track_draws_the_same_frames():
    # Full scenery at the Udacity size, where coplanar surfaces (kerbs on the road, the road on
    # the verge) meet: the draw order must not depend on where render states lie in memory.
    track = load_track("mountain")
    frames = []
    scenes = [Scene(track), Scene(track)]  # two open at once, then one more after they close
    try:
        frames += [render_start(scene, 320, 160) for scene in scenes]
    finally:
        for scene in scenes:
            scene.close()
    with Scene(track) as later:
        frames.append(render_start(later, 320, 160))
    for frame in frames[1:]:
        np.testing.assert_array_equal(frame, frames[0])


def test_scenes_on_one_track_reuse_its_scenery_and_textures_unchanged():
    from test_golden import looks_the_same

    from clonedrive.sim import reuse
    from clonedrive.sim.conditions import Conditions
    from clonedrive.sim.scene import _texture_images

    reuse.forget()
    worn = Conditions(road_wear=0.6)
    with Scene("mountain") as fresh:
        image_fresh = render_start(fresh)
    with Scene("mountain", conditions=worn) as fresh_worn:
        image_worn = render_start(fresh_worn)
    with Scene("mountain") as again:
        image_again = render_start(again)
        assert again.scenery is fresh.scenery  # reused, not rebuilt
    with Scene("mountain", conditions=worn) as again_worn:
        assert again_worn.scenery is fresh_worn.scenery
        image_again_worn = render_start(again_worn)
    # What was handed out is what a fresh build gives, after four scenes used it.
    rebuilt = build_scenery(load_track("mountain"))
    for material, mesh in rebuilt.meshes.items():
        kept = again.scenery.meshes[material].arrays()
        for key, array in mesh.arrays().items():
            np.testing.assert_array_equal(kept[key], array)
    style, width = again.scenery.style, float(np.median(again.track.width))
    kept_images = reuse.reused(("textures", "mountain", style, width, 0.0), lambda: None)
    for name, image in _texture_images("mountain", style, width, 0.0).items():
        np.testing.assert_array_equal(kept_images[name], image)
    # The frames are the same, bit for bit (with Panda3D's state-sorted draw order a process's
    # later scenes differed from its first in a few dozen pixels), and the worn road is another
    # look, not mixed up with the plain one.
    np.testing.assert_array_equal(image_again, image_fresh)
    np.testing.assert_array_equal(image_again_worn, image_worn)
    assert not looks_the_same(image_worn, image_fresh)
    # Another track of the same theme gets its own scenery.
    with Scene("gen2:hard:2000", scenery=False) as other:
        assert other.scenery is not fresh.scenery
    reuse.forget()
    assert not reuse._kept


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


#: Generated lake tracks whose road dips lower than the bridge deck less 2.2 m: before the water
#: level also cleared the road, stretches of these ran under the lake.
LOW_ROAD_TRACKS = ["gen2:easy:2001", "gen2:medium:2001", "gen2:hard:2002", "gen2:hard:2003"]


@pytest.mark.parametrize("name", ["lake", *LOW_ROAD_TRACKS])
def test_the_water_lies_below_the_whole_road(name):
    track = load_track(name)
    bridge = find_bridge(track)
    level = water_level(track, bridge)
    on_bridge = bridge.contains(track.s, track.length_m)
    assert level <= track.xyz[on_bridge, 2].min() - WATER_BELOW_BRIDGE_M
    assert level <= track.xyz[:, 2].min() - WATER_BELOW_ROAD_M
    if name == "lake":  # the lake track's road clears the bridge's water: its look is unchanged
        assert level == pytest.approx(track.xyz[on_bridge, 2].min() - WATER_BELOW_BRIDGE_M)


def test_the_camera_sees_road_not_water_on_the_low_s_bends():
    # gen2:medium:2001's S-bends at 370-490 m lie below its bridge deck less 2.2 m: the camera
    # on the centreline there saw only water (blue minus red 68-78 here), and networks drove
    # off the road where they could not see it
    track = load_track("gen2:medium:2001")
    with Scene(track) as scene, CameraRig(scene, ("center",), 80, 40) as rig:
        for s in (380.0, 440.0):
            x, y, z = track.point(s)
            image = rig.render(x, y, z, float(track.heading_at(s)))["center"].astype(float)
            ahead = image[24:32, 30:50]  # the road just ahead of the bonnet
            red, blue = ahead[..., 0].mean(), ahead[..., 2].mean()
            assert blue - red < 25.0, s  # grey asphalt (about -11); the water is blue
