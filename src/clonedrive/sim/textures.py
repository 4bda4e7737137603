"""Procedural textures for the scene, generated with NumPy at scene build time (nothing on disk).

Every function takes a ``np.random.Generator`` and returns a tileable ``uint8`` image, rows top to
bottom: (H, W, 3) RGB or (H, W, 4) RGBA. :func:`to_panda_texture` turns one into a Panda3D
``Texture``. Sizes are powers of two (the software renderer wants them) and small: at 320x160 a
texel of a few centimetres is finer than a pixel a few metres ahead.

Colour textures that are tinted by vertex colours (ground, rock) are grey around 0.8, so that
``vertex colour x texel`` keeps the vertex colour as the mean.
"""

from __future__ import annotations

import numpy as np

#: Road texture layout: u runs across the road (0 = left edge, 1 = right edge), v along it.
ROAD_TEXTURE_SIZE = (512, 256)  # (rows along the road, columns across)
#: Metres of road one road texture repeat covers along the road.
ROAD_TEXTURE_REPEAT_M = 16.0
#: Edge line: distance from the road edge to the line's outer side, and its width [m].
EDGE_LINE_INSET_M = 0.25
EDGE_LINE_WIDTH_M = 0.22


def fractal_noise(
    rng: np.random.Generator, shape: tuple[int, int], beta: float = 2.0, *, low_cut: float = 1.0
) -> np.ndarray:
    """Tileable 1/f^beta noise of ``shape``, zero mean and unit standard deviation."""
    rows, cols = shape
    white = rng.standard_normal(shape)
    fy = np.fft.fftfreq(rows)[:, None] * rows
    fx = np.fft.fftfreq(cols)[None, :] * cols
    radius = np.maximum(np.hypot(fx, fy), low_cut)
    spectrum = np.fft.fft2(white) / radius ** (beta / 2.0)
    spectrum[0, 0] = 0.0
    field = np.real(np.fft.ifft2(spectrum))
    return (field - field.mean()) / max(float(field.std()), 1e-9)


def _to_uint8(image: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(image), 0, 255).astype(np.uint8)


def _speckles(rng: np.random.Generator, shape: tuple[int, int], density: float) -> np.ndarray:
    """-1/0/+1 map of isolated dark and light grains."""
    draw = rng.random(shape)
    return np.where(draw < density / 2, -1.0, np.where(draw > 1 - density / 2, 1.0, 0.0))


def asphalt(
    rng: np.random.Generator,
    *,
    base_rgb: tuple[float, float, float],
    road_width_m: float,
    edge_rgb: tuple[float, float, float] = (205.0, 170.0, 40.0),
    centre_line: bool = False,
    tyre_tracks: float = 0.0,
    wear: float = 0.0,
) -> np.ndarray:
    """Road texture: grainy asphalt with the edge lines painted in (u across, v along).

    ``tyre_tracks`` in [0, 1] darkens two bands where wheels run (the mountain road's look).
    ``wear`` in [0, 1]: patchier asphalt and edge lines faded away in patches (1: mostly gone).
    """
    rows, cols = ROAD_TEXTURE_SIZE
    coarse = fractal_noise(rng, (rows, cols), 2.6)
    fine = fractal_noise(rng, (rows, cols), 1.4)
    grain = _speckles(rng, (rows, cols), 0.05)
    shade = 1.0 + (0.10 + 0.15 * wear) * coarse + 0.10 * fine + 0.05 * grain
    u = (np.arange(cols) + 0.5) / cols
    if tyre_tracks > 0:
        metres = u * road_width_m
        half = road_width_m / 2
        tracks = np.zeros(cols)
        for lane_centre in (half / 2, half + half / 2):
            for wheel in (-0.8, 0.8):
                tracks += np.exp(-(((metres - lane_centre - wheel) / 0.45) ** 2))
        shade = shade * (1.0 - tyre_tracks * 0.16 * tracks[None, :])
    image = np.asarray(base_rgb, dtype=float)[None, None, :] * shade[..., None]
    metres = u * road_width_m
    from_edge = np.minimum(metres, road_width_m - metres)
    line = (from_edge >= EDGE_LINE_INSET_M) & (from_edge < EDGE_LINE_INSET_M + EDGE_LINE_WIDTH_M)
    worn = 0.9 + 0.1 * fine[:, line]
    paint = np.asarray(edge_rgb)[None, None, :] * worn[..., None]
    if wear > 0:  # paint gone where the coarse noise is high, more of it the more worn
        gone = np.clip((coarse[:, line] + 1.6 - 3.2 * wear) * -1.5, 0.0, 1.0)[..., None]
        paint = paint * (1.0 - gone) + image[:, line, :] * gone
    image[:, line, :] = paint
    if centre_line:
        centre = np.abs(metres - road_width_m / 2) < 0.07
        dash = (np.arange(rows) / rows * ROAD_TEXTURE_REPEAT_M) % 6.0 < 3.0
        image[np.ix_(dash, centre)] = (225.0, 225.0, 215.0)
    return _to_uint8(image)


def ground_detail(rng: np.random.Generator, size: int = 128) -> np.ndarray:
    """Grey detail texture for grass, dirt and gravel (tinted by vertex colours)."""
    coarse = fractal_noise(rng, (size, size), 2.2)
    fine = fractal_noise(rng, (size, size), 0.5)
    grain = _speckles(rng, (size, size), 0.18)
    value = 205.0 * (1.0 + 0.10 * coarse + 0.12 * fine + 0.12 * grain)
    # a touch of colour variation so tinted grass is not flat
    rgb = np.stack([value * (1 + 0.04 * coarse), value, value * (1 - 0.04 * coarse)], axis=-1)
    return _to_uint8(rgb)


def rock(rng: np.random.Generator, size: int = 128) -> np.ndarray:
    """Grey rock texture with horizontal strata and cracks (tinted by vertex colours)."""
    blotch = fractal_noise(rng, (size, size), 2.4)
    fine = fractal_noise(rng, (size, size), 1.0)
    rows = np.arange(size)[:, None]
    warp = 6.0 * fractal_noise(rng, (size, size), 3.0)
    strata = np.sin((rows + warp) * (2 * np.pi * 5 / size)) ** 7
    cracks = np.clip(-fractal_noise(rng, (size, size), 1.6) - 1.6, 0, None)
    value = 200.0 * (1.0 + 0.16 * blotch + 0.10 * fine + 0.10 * strata - 0.5 * cracks)
    return _to_uint8(np.repeat(value[..., None], 3, axis=-1))


def water(rng: np.random.Generator, size: int = 64) -> np.ndarray:
    """Lake water: blue with soft ripples and glints."""
    ripple = fractal_noise(rng, (size, size), 1.8)
    glint = np.clip(fractal_noise(rng, (size, size), 0.6) - 2.0, 0, None)
    base = np.array([62.0, 104.0, 140.0])
    image = base[None, None, :] * (1.0 + 0.10 * ripple[..., None]) + 90.0 * glint[..., None]
    return _to_uint8(image)


def kerb(size: int = 64) -> np.ndarray:
    """Red and white kerb stripes along v (one red and one white block per repeat)."""
    rows = np.arange(size)
    red = (rows < size // 2)[:, None, None]
    image = np.where(red, np.array([200.0, 40.0, 45.0]), np.array([235.0, 232.0, 228.0]))
    image = np.broadcast_to(image, (size, 8, 3)).copy()
    image[:, :1] *= 0.8  # a darker lip at the road side
    return _to_uint8(image)


def barrier(size: int = 64) -> np.ndarray:
    """Concrete barrier block: grey body with a yellow/black chevron band (u along the block)."""
    rows, cols = size // 2, size
    grid_r, grid_c = np.mgrid[0:rows, 0:cols]
    image = np.full((rows, cols, 3), 165.0)
    band = (grid_r > rows * 0.2) & (grid_r < rows * 0.75)
    stripe = ((grid_c + grid_r) // 6) % 2 == 0
    image[band & stripe] = (215.0, 180.0, 30.0)
    image[band & ~stripe] = (30.0, 30.0, 30.0)
    image[grid_r < 2] = 190.0
    return _to_uint8(image)


def chevron_sign(size: int = 64) -> np.ndarray:
    """Black sign with a white chevron pointing right (flip u for left)."""
    grid_r, grid_c = np.mgrid[0:size, 0:size]
    image = np.full((size, size, 3), 25.0)
    centre = size / 2
    offset = np.abs(grid_r - centre) * 0.7
    arrow = np.abs((grid_c - offset) - size * 0.45) < size * 0.12
    image[arrow] = (235.0, 235.0, 235.0)
    border = (grid_r < 3) | (grid_r >= size - 3) | (grid_c < 3) | (grid_c >= size - 3)
    image[border] = (200.0, 200.0, 200.0)
    return _to_uint8(image)


def tree_atlas(rng: np.random.Generator, kinds: tuple[str, ...]) -> np.ndarray:
    """RGBA atlas of tree sprites side by side, 64x128 each; alpha is 0 or 255.

    Kinds: ``"pine"`` (tall conifer), ``"broadleaf"`` (round crown), ``"autumn"`` (orange
    broadleaf), ``"bush"`` (low shrub in the lower half of its cell).
    """
    width, height = 64, 128
    atlas = np.zeros((height, width * len(kinds), 4), dtype=float)
    rows, cols = np.mgrid[0:height, 0:width]
    y = 1.0 - (rows + 0.5) / height  # 0 at the bottom, 1 at the top
    x = (cols + 0.5) / width - 0.5
    for index, kind in enumerate(kinds):
        leaf_noise = fractal_noise(rng, (height, width), 0.9)
        shade_noise = fractal_noise(rng, (height, width), 2.0)
        cell = np.zeros((height, width, 4))
        trunk_top = {"pine": 0.45, "broadleaf": 0.45, "autumn": 0.45, "bush": 0.05}[kind]
        trunk = (np.abs(x) < 0.035 + 0.02 * (1 - y)) & (y < trunk_top + 0.1)
        if kind == "pine":
            # stacked tiers of needles: width shrinks toward the top, with a sawtooth per tier
            tier = (y * 7.0) % 1.0
            half_width = (1.0 - y) * 0.42 * (0.55 + 0.45 * (1 - tier)) + 0.02
            crown = (y > 0.22) & (np.abs(x) < half_width + 0.05 * leaf_noise) & (y < 0.99)
            green = np.array([58.0, 88.0, 42.0])
        elif kind == "bush":
            radius = np.hypot(x / 0.48, (y - 0.2) / 0.2)
            crown = radius < 1.0 + 0.18 * leaf_noise
            green = np.array([88.0, 104.0, 48.0])
        else:
            blobs = np.hypot(x / 0.44, (y - 0.68) / 0.3)
            crown = (blobs < 1.0 + 0.22 * leaf_noise) & (y > 0.3)
            green = np.array([196.0, 112.0, 36.0] if kind == "autumn" else [78.0, 112.0, 48.0])
        light = 1.0 + 0.25 * x * -2.0 + 0.12 * shade_noise + 0.15 * (y - 0.5)
        cell[trunk] = (*np.array([88.0, 64.0, 44.0]), 255.0)
        crown_rgb = green[None, :] * light[crown][:, None]
        crown_rgb *= np.where(rng.random(crown_rgb.shape[0]) < 0.12, 0.72, 1.0)[:, None]
        cell[crown, :3] = crown_rgb
        cell[crown, 3] = 255.0
        atlas[:, index * width : (index + 1) * width] = cell
    return _to_uint8(atlas)


def to_panda_texture(image: np.ndarray, name: str, *, mipmaps: bool = True, clamp: bool = False):
    """A Panda3D ``Texture`` holding ``image`` (rows top to bottom, RGB or RGBA uint8)."""
    from panda3d.core import SamplerState, Texture

    rows, cols, channels = image.shape
    texture = Texture(name)
    fmt = Texture.F_rgba8 if channels == 4 else Texture.F_rgb8
    texture.setup_2d_texture(cols, rows, Texture.T_unsigned_byte, fmt)
    # Panda stores rows bottom to top; the channel order of ``set_ram_image_as`` is given.
    flipped = np.ascontiguousarray(image[::-1])
    texture.set_ram_image_as(flipped.tobytes(), "RGBA" if channels == 4 else "RGB")
    texture.set_magfilter(SamplerState.FT_nearest)
    texture.set_minfilter(
        SamplerState.FT_nearest_mipmap_nearest if mipmaps else SamplerState.FT_nearest
    )
    wrap = SamplerState.WM_clamp if clamp else SamplerState.WM_repeat
    texture.set_wrap_u(wrap)
    texture.set_wrap_v(wrap)
    return texture
