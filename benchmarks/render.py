"""Rendered camera frames per second: headless, one process, the 3-camera Udacity rig at
320x160 on the lake and mountain tracks with full scenery, the car driving along the centreline
at 30 mph with 15 control steps per second.

``--renderer software|egl|auto`` chooses who draws (sim/engine.py); ``benchmarks/egl.py`` compares
the two in one run (``egl_ratio``).

**``render_ratio`` is retired** (kept in the JSON line for comparison with earlier runs, with no
target): its reference, a bare textured grid of the same triangle count, measured the fill cost
of our scene's look, which is a choice, not overhead. The figures that compare like with like
are ``rig_ratio`` here, ``crop_speedup`` and ``loop_ratio`` (``benchmarks/crop.py``,
``benchmarks/evaluate.py``) and ``egl_ratio`` (``benchmarks/egl.py``).

The retired reference, measured in the same run: a bare Panda3D offscreen scene with the same
number of triangles (a textured ground grid split into 96 m cells, as our scene is), the same
cameras, lenses, resolution and read-back of every frame to a NumPy array. ``render_ratio`` =
our frames/s / the bare scene's frames/s on the same track's triangle count: what our scene
costs beyond what Panda3D itself needs for that much geometry (1.0 is no overhead).
``rig_ratio`` = our camera rig / the same scene rendered through bare Panda3D calls (pose,
render, raw RAM image): the overhead of our per-frame code alone, apart from the scene's content.

The bare grid spreads its triangles evenly over 960 m, so a camera sees few of them; ours lie
along the road the camera is on. ``drawn_per_camera`` counts the triangles Panda3D's culling
hands the renderer in each frame (the nodes whose bounds meet a camera's frustum, within their
LOD distance; the same count for both scenes), and ``render_ratio_drawn`` compares our scene
against a denser bare grid that draws as many triangles per frame as ours does.
``render_ratio_paths`` compares it against that grid with its pixels shaded as ours are
(per-vertex colours modulating a mipmapped texture: the software renderer's slower inner loop
that baked light and fog need); what is left is our content (overdraw, clipping, state changes).

Prints figures per track (wall-clock and this process's CPU time: other work on the machine
slows the wall clock, not the CPU figure) and ends with one JSON line:
``{"render_ratio": <slower track>, "camera_frames_per_s": <slower track, wall clock>, ...}``.

    python benchmarks/render.py [--steps 600] [--tracks lake mountain] [--renderer software]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time

import numpy as np

from clonedrive.base.udacity_spec import CONTROL_HZ
from clonedrive.world.vehicle import MPH_TO_MPS


def drawn_triangles(root, camera) -> int:
    """Triangles in the Geoms that view-frustum culling hands the renderer for ``camera`` (a
    NodePath of a Camera): every visible GeomNode whose bounds meet the lens's frustum and,
    below an LODNode, lies within its switch distance. Back faces and the parts the rasteriser
    clips away are counted too, alike in both scenes."""
    from panda3d.core import LODNode

    frustum = camera.node().get_lens().make_bounds()
    frustum.xform(camera.get_mat(root))
    eye = camera.get_pos(root)
    lod_type = LODNode.get_class_type()
    total = 0
    for path in root.find_all_matches("**/+GeomNode"):
        if path.is_hidden():
            continue
        near_enough = True
        ancestor = path.get_parent()
        while near_enough and not ancestor.is_empty():
            node = ancestor.node()
            if node.is_of_type(lod_type):
                distance = (root.get_relative_point(ancestor, node.get_center()) - eye).length()
                near_enough = node.get_out(0) <= distance < node.get_in(0)
            ancestor = ancestor.get_parent()
        if not near_enough:
            continue
        bounds = path.get_bounds()
        bounds.xform(path.get_parent().get_mat(root))
        if frustum.contains(bounds):
            geom_node = path.node()
            total += sum(geom_node.get_geom(i).get_primitive(j).get_num_faces()
                         for i in range(geom_node.get_num_geoms())
                         for j in range(geom_node.get_geom(i).get_num_primitives()))
    return total


def measure(track_name: str, steps: int, warmup: int = 20, renderer: str = "software") -> dict:
    from clonedrive.sim.cameras import CameraRig
    from clonedrive.sim.scene import Scene
    from clonedrive.world.catalog import load_track

    track = load_track(track_name)
    step_m = 30.0 * MPH_TO_MPS / CONTROL_HZ  # 30 mph, one control step
    build_start = time.perf_counter()
    with Scene(track, renderer=renderer) as scene, CameraRig(scene) as rig:
        build_s = time.perf_counter() - build_start

        def drive(count: int, start_m: float) -> None:
            for i in range(count):
                s = start_m + i * step_m
                x, y, z = track.point(s)
                grade = float(track.grade(s))
                rig.render(float(x), float(y), float(z), float(track.heading_at(s)),
                           pitch_rad=float(grade))

        def drive_raw(count: int, start_m: float) -> None:
            """The same frames through bare Panda3D calls: pose, render, raw RAM image."""
            textures = list(rig._textures.values())
            for i in range(count):
                s = start_m + i * step_m
                x, y, z = track.point(s)
                scene.car.set_pos_hpr(float(x), float(y), float(z),
                                      math.degrees(float(track.heading_at(s))) - 90.0,
                                      math.degrees(float(track.grade(s))), 0.0)
                scene.follow.set_pos(float(x), float(y), float(z))
                scene.engine.render_frame()
                for texture in textures:
                    texture.get_ram_image()

        drive(warmup, 0.0)
        wall_start, cpu_start = time.perf_counter(), time.process_time()
        drive(steps, warmup * step_m)
        wall_s = time.perf_counter() - wall_start
        cpu_s = time.process_time() - cpu_start
        raw_start = time.process_time()
        drive_raw(steps, warmup * step_m)
        raw_cpu_s = time.process_time() - raw_start
        cameras = len(rig.cameras)
        triangles = scene.triangle_count
        drawn = []
        for i in range(0, steps, 20):  # after timing: counting is not part of a frame's cost
            s = (warmup + i) * step_m
            x, y, z = track.point(s)
            scene.set_car_pose(float(x), float(y), float(z), float(track.heading_at(s)),
                               float(track.grade(s)))
            drawn += [drawn_triangles(scene.root, node) for node in rig._nodes.values()]
    return {
        "track": track_name,
        "steps": steps,
        "cameras": cameras,
        "build_s": round(build_s, 2),
        "triangles": triangles,
        "drawn_per_camera": float(np.mean(drawn)),
        "steps_per_s": steps / wall_s,
        "camera_frames_per_s": steps * cameras / wall_s,
        "cpu_camera_frames_per_s": steps * cameras / cpu_s,
        "raw_cpu_camera_frames_per_s": steps * cameras / raw_cpu_s,
    }


def _bare_grid(triangles: int, size_m: float = 960.0, cell_m: float = 96.0, *,
               our_pixels: bool = False):
    """A flat, textured ground of about ``triangles`` triangles in ``cell_m`` square nodes.

    ``our_pixels``: shade its pixels as ours are (per-vertex colours modulating the texture,
    mipmapped), so the software renderer fills them through the same inner loop."""
    from panda3d.core import (
        Geom,
        GeomNode,
        GeomTriangles,
        GeomVertexData,
        GeomVertexFormat,
        GeomVertexWriter,
        NodePath,
        Texture,
    )

    cells = int(size_m / cell_m)
    per_cell = max(2, triangles // (cells * cells))
    side = max(1, int(round((per_cell / 2) ** 0.5)))  # quads per cell side
    root = NodePath("bare")
    texture = Texture("checker")
    texture.setup_2d_texture(256, 256, Texture.T_unsigned_byte, Texture.F_rgb)
    checker = ((np.indices((256, 256)).sum(axis=0) // 32) % 2 * 80 + 60).astype(np.uint8)
    texture.set_ram_image(np.repeat(checker[..., None], 3, axis=2).tobytes())
    if our_pixels:
        from panda3d.core import SamplerState

        texture.set_minfilter(SamplerState.FT_nearest_mipmap_nearest)
        texture.generate_ram_mipmap_images()
    vertex_format = GeomVertexFormat.get_v3c4t2() if our_pixels else GeomVertexFormat.get_v3t2()
    step = cell_m / side
    for i in range(cells):
        for j in range(cells):
            data = GeomVertexData("cell", vertex_format, Geom.UH_static)
            vertex, uv = GeomVertexWriter(data, "vertex"), GeomVertexWriter(data, "texcoord")
            colour = GeomVertexWriter(data, "color") if our_pixels else None
            for a in range(side + 1):
                for b in range(side + 1):
                    x, y = i * cell_m + a * step - size_m / 2, j * cell_m + b * step - size_m / 2
                    vertex.add_data3(x, y, 0.0)
                    uv.add_data2(a / 4.0, b / 4.0)
                    if colour is not None:  # a varying tint, as baked light and haze are
                        colour.add_data4(0.7 + 0.1 * (a % 3), 0.75, 0.7 + 0.1 * (b % 3), 1.0)
            tris = GeomTriangles(Geom.UH_static)
            for a in range(side):
                for b in range(side):
                    k = a * (side + 1) + b
                    tris.add_vertices(k, k + side + 1, k + 1)
                    tris.add_vertices(k + 1, k + side + 1, k + side + 2)
            geom = Geom(data)
            geom.add_primitive(tris)
            node = GeomNode("cell")
            node.add_geom(geom)
            root.attach_new_node(node)
    # A textured backdrop all round (our scene has its sky cylinder and hills), so that every
    # pixel of the bare frame is textured too, as ours are.
    data = GeomVertexData("backdrop", vertex_format, Geom.UH_static)
    vertex, uv = GeomVertexWriter(data, "vertex"), GeomVertexWriter(data, "texcoord")
    colour = GeomVertexWriter(data, "color") if our_pixels else None
    segments, radius, height = 64, size_m / 2, 200.0
    for k in range(segments + 1):
        angle = 2 * np.pi * k / segments
        for z in (-1.0, height):
            vertex.add_data3(radius * np.cos(angle), radius * np.sin(angle), z)
            uv.add_data2(k / 4.0, z / 50.0)
            if colour is not None:
                colour.add_data4(0.8, 0.85, 0.9 if z > 0 else 0.7, 1.0)
    tris = GeomTriangles(Geom.UH_static)
    for k in range(segments):
        a = 2 * k
        tris.add_vertices(a, a + 2, a + 1)
        tris.add_vertices(a + 1, a + 2, a + 3)
    geom = Geom(data)
    geom.add_primitive(tris)
    node = GeomNode("backdrop")
    node.add_geom(geom)
    backdrop = root.attach_new_node(node)
    backdrop.set_two_sided(True)
    root.set_texture(texture)
    return root, cells * cells * side * side * 2 + 2 * segments


def measure_bare(triangles: int, steps: int, cameras: int = 3, width: int = 320,
                 height: int = 160, warmup: int = 20, *, our_pixels: bool = False,
                 renderer: str = "software") -> dict:
    """The same camera loop over a bare grid scene of ``triangles`` triangles."""
    from panda3d.core import Camera, NodePath, PerspectiveLens

    from clonedrive.sim.cameras import UDACITY_RIG
    from clonedrive.sim.engine import RenderEngine, texture_rgb
    from clonedrive.sim.scene import FAR_M, NEAR_M

    engine = RenderEngine(renderer=renderer)
    try:
        world = NodePath("world")
        grid, made = _bare_grid(triangles, our_pixels=our_pixels)
        grid.reparent_to(world)
        car = world.attach_new_node("car")
        textures = []
        for name in list(UDACITY_RIG)[:cameras]:
            mount = UDACITY_RIG[name]
            buffer, texture = engine.make_buffer(f"bare-{name}", width, height)
            lens = PerspectiveLens()
            lens.set_fov(mount.horizontal_fov_deg(width, height), mount.vertical_fov_deg)
            lens.set_near_far(NEAR_M, FAR_M)
            node = car.attach_new_node(Camera(f"bare-{name}", lens))
            node.node().set_scene(world)
            x, up, forward = mount.position_m
            node.set_pos(x, forward, up)
            node.set_hpr(0.0, -mount.pitch_down_deg, 0.0)
            buffer.make_display_region().set_camera(node)
            buffer.set_clear_color((0.5, 0.6, 0.8, 1.0))
            textures.append(texture)
        step_m = 30.0 * MPH_TO_MPS / CONTROL_HZ

        def drive(count: int, start_m: float) -> None:
            for i in range(count):
                car.set_pos(-400.0 + start_m + i * step_m, 3.0, 0.0)
                car.set_h(-90.0)
                engine.render_frame()
                for texture in textures:
                    texture_rgb(texture)

        drive(warmup, 0.0)
        wall_start, cpu_start = time.perf_counter(), time.process_time()
        drive(steps, warmup * step_m)
        wall_s = time.perf_counter() - wall_start
        cpu_s = time.process_time() - cpu_start
        drawn = []
        for i in range(0, steps, 20):
            car.set_pos(-400.0 + (warmup + i) * step_m, 3.0, 0.0)
            drawn += [drawn_triangles(world, node) for node in world.find_all_matches("**/+Camera")]
    finally:
        engine.close()
    return {"triangles": made, "drawn_per_camera": float(np.mean(drawn)),
            "camera_frames_per_s": steps * cameras / wall_s,
            "cpu_camera_frames_per_s": steps * cameras / cpu_s}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=600, help="control steps per track")
    parser.add_argument("--tracks", nargs="+", default=["lake", "mountain"])
    parser.add_argument("--renderer", choices=("software", "egl", "auto"), default="software",
                        help="who draws the frames (sim/engine.py)")
    args = parser.parse_args()
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"load average before: {load:.2f} on {os.cpu_count()} CPUs")
    results = {}
    for name in args.tracks:
        result = measure(name, args.steps, renderer=args.renderer)
        bare = measure_bare(result["triangles"], args.steps, result["cameras"],
                            renderer=args.renderer)
        # The same grid made denser, until a frame of it draws as many triangles as ours do.
        denser = round(bare["triangles"] * result["drawn_per_camera"]
                       / max(bare["drawn_per_camera"], 1.0))
        denser = max(denser, bare["triangles"])
        bare_drawn = measure_bare(denser, args.steps, result["cameras"], renderer=args.renderer)
        # That grid again with its pixels shaded as ours are (vertex colours x mipmapped
        # texture): what our scene costs beyond the triangles drawn and the pixel path chosen.
        bare_paths = measure_bare(denser, args.steps, result["cameras"], our_pixels=True,
                                  renderer=args.renderer)
        # CPU time is the fairer basis: other processes on the machine slow the wall clock.
        result["bare"] = bare
        result["bare_drawn"] = bare_drawn
        result["render_ratio"] = (result["cpu_camera_frames_per_s"]
                                  / bare["cpu_camera_frames_per_s"])
        result["render_ratio_drawn"] = (result["cpu_camera_frames_per_s"]
                                        / bare_drawn["cpu_camera_frames_per_s"])
        result["bare_paths"] = bare_paths
        result["render_ratio_paths"] = (result["cpu_camera_frames_per_s"]
                                        / bare_paths["cpu_camera_frames_per_s"])
        result["rig_ratio"] = (result["cpu_camera_frames_per_s"]
                               / result["raw_cpu_camera_frames_per_s"])
        results[name] = result
        print(
            f"{name:10s} {result['triangles']:6d} triangles, built in {result['build_s']:.2f} s: "
            f"{result['steps_per_s']:6.1f} three-camera steps/s = "
            f"{result['camera_frames_per_s']:6.1f} camera frames/s wall clock, "
            f"{result['cpu_camera_frames_per_s']:6.1f} per CPU second"
        )
        print(
            f"{'':10s} bare Panda3D grid of {bare['triangles']} triangles: "
            f"{bare['cpu_camera_frames_per_s']:6.1f} camera frames per CPU second -> "
            f"render_ratio {result['render_ratio']:.2f} (retired, no target)"
        )
        print(
            f"{'':10s} triangles drawn per camera frame: ours {result['drawn_per_camera']:.0f}, "
            f"the bare grid's {bare['drawn_per_camera']:.0f}; a bare grid of "
            f"{bare_drawn['triangles']} triangles draws {bare_drawn['drawn_per_camera']:.0f}: "
            f"{bare_drawn['cpu_camera_frames_per_s']:6.1f} frames per CPU second -> "
            f"render_ratio_drawn {result['render_ratio_drawn']:.2f}"
        )
        print(
            f"{'':10s} that grid with our pixel path (vertex colours x mipmapped texture): "
            f"{bare_paths['cpu_camera_frames_per_s']:6.1f} frames per CPU second -> "
            f"render_ratio_paths {result['render_ratio_paths']:.2f}"
        )
        print(
            f"{'':10s} our scene through bare Panda3D calls: "
            f"{result['raw_cpu_camera_frames_per_s']:6.1f} camera frames per CPU second -> "
            f"our rig's own overhead ratio {result['rig_ratio']:.2f}"
        )
    slowest = min(results.values(), key=lambda r: r["camera_frames_per_s"])
    print(json.dumps({
        "render_ratio": round(min(r["render_ratio"] for r in results.values()), 3),
        "render_ratio_per_track": {name: round(r["render_ratio"], 3)
                                   for name, r in results.items()},
        "render_ratio_drawn": round(min(r["render_ratio_drawn"] for r in results.values()), 3),
        "render_ratio_paths": round(min(r["render_ratio_paths"] for r in results.values()), 3),
        "drawn_per_camera": {name: round(r["drawn_per_camera"]) for name, r in results.items()},
        "rig_ratio": round(min(r["rig_ratio"] for r in results.values()), 3),
        "camera_frames_per_s": round(slowest["camera_frames_per_s"], 1),
        "per_track": {name: round(r["camera_frames_per_s"], 1) for name, r in results.items()},
        "cpu_camera_frames_per_s": {
            name: round(r["cpu_camera_frames_per_s"], 1) for name, r in results.items()
        },
        "load_average": round(load, 2),
        "renderer": args.renderer,
        "render_ratio_retired": True,
    }))


if __name__ == "__main__":
    main()
