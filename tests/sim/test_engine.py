"""The renderer choice (sim/engine.py): software, EGL, and auto.

EGL opens here and in CI on Mesa's llvmpipe (a CPU implementation of OpenGL): it draws the same
scene with smoother texture sampling, so frames differ from the software renderer's by a few grey
levels (measured over lake and mountain, a frame every 20 m: 7.5 and 5.3 on average, at most 8.9
in one frame), and auto keeps the software renderer there.
"""

from __future__ import annotations

import numpy as np
import pytest

from clonedrive.sim import engine
from clonedrive.sim.cameras import FILL_VALUE, CameraRig
from clonedrive.sim.scene import Scene
from clonedrive.world.catalog import load_track

#: Mean absolute difference [grey levels] allowed between an EGL frame and a software one.
RENDERER_DIFFERENCE_BOUND = 12.0

needs_egl = pytest.mark.skipif(engine.probe_egl() is None,
                               reason="Panda3D's EGL pipe does not open on this machine")


def test_renderer_names_are_checked():
    assert engine.resolve_renderer("software") == "software"
    assert engine.resolve_renderer("egl") == "egl"
    with pytest.raises(ValueError, match="unknown renderer 'vulkan'"):
        engine.check_renderer("vulkan")
    with pytest.raises(ValueError, match="unknown renderer"):
        from clonedrive.sim.simulator import SimConfig

        SimConfig(renderer="opengl")


@pytest.mark.parametrize(("found", "expected"), [
    (None, "software"),
    ("llvmpipe (LLVM 15.0.6, 256 bits)", "software"),
    ("softpipe", "software"),
    ("NVIDIA H200/PCIe/SSE2", "egl"),
    ("AMD Radeon Graphics (radeonsi, gfx1103, LLVM 17.0.6, DRM 3.57)", "egl"),
])
def test_auto_picks_egl_only_on_a_gpu(monkeypatch, found, expected):
    monkeypatch.setattr(engine, "probe_egl", lambda: found)
    assert engine.resolve_renderer("auto") == expected
    info = engine.renderer_info("auto")
    assert info["renderer"] == "auto" and info["renderer_used"] == expected
    if expected == "software":
        assert info["gl_renderer"] == engine.SOFTWARE_DESCRIPTION
    else:
        assert info["gl_renderer"] == found


@needs_egl
def test_egl_frames_look_like_the_software_renderers():
    track = load_track("lake")
    poses = []
    for s in (30.0, 150.0, 400.0, 700.0):
        x, y, z = track.point(s)
        poses.append((float(x), float(y), float(z), float(track.heading_at(s)),
                      float(track.grade(s))))
    frames = {}
    for renderer in ("software", "egl"):
        with Scene(track, renderer=renderer) as scene, \
                CameraRig(scene, cameras=("center",)) as rig, \
                CameraRig(scene, cameras=("center",), rows=(80, 135)) as strip:
            frames[renderer] = [rig.render(*pose)["center"] for pose in poses]
            cropped = strip.render(*poses[0])["center"]
            assert (cropped[:80] == FILL_VALUE).all() and cropped[80:135].any()
            if renderer == "egl":
                assert not engine.is_software_gl("NVIDIA") and scene.engine.gl_renderer()
    for software, egl in zip(frames["software"], frames["egl"], strict=True):
        assert software.shape == egl.shape == (160, 320, 3)
        difference = np.abs(software.astype(np.int16) - egl.astype(np.int16)).mean()
        assert difference < RENDERER_DIFFERENCE_BOUND
