"""Which rows of a camera frame a model looks at: its input crop.

Every network of ours crops its 160x320 input with a ``Cropping2D`` first (the write-up's
crop keeps rows 80-135, ``--crop-top 60`` keeps 60-135). Training computes only those rows
(data.augment), and the closed loop renders only those rows (sim.cameras) when nothing else
needs the full frame. :func:`visible_rows` reads the crop from the model itself, so a policy
tells the renderer what it needs. The crop's default rows are defined here, once: the networks
(model.architectures) and the rows training caches (data.dataset) both follow them.
"""

from __future__ import annotations

from clonedrive.base.udacity_spec import IMAGE_SHAPE

#: Rows cut from the top (sky, trees) and bottom (bonnet) of the frame, in pixels. With the
#: Udacity camera (60 deg vertical field, pitched 9.4 deg down, 1.2 m up) row 80 looks at the
#: road about 7 m ahead and the horizon is near row 55: the write-up's crop sees 2-7 m of road.
#: A smaller ``crop_top_px`` (60: about 36 m) lets a speed head see a bend before it brakes.
CROP_TOP_PX = 80
CROP_BOTTOM_PX = 25

#: Layers that may come before the crop: they act on each pixel alone, so cropping first or
#: after gives the same values.
_BEFORE_CROP = ("InputLayer", "Rescaling")


def visible_rows(model) -> tuple[int, int] | None:
    """``(first, end)``: the rows of a 160-row frame that ``model`` looks at, when its first
    layer after the input is a ``Cropping2D`` (as in all of ours; per-pixel ``Rescaling``
    layers before it do not count); None when it sees them all, crops otherwise, or has no
    Keras layers to read. A model that carries its rows already (a traced model for a worker
    process) answers with those."""
    if hasattr(model, "visible_rows"):
        return model.visible_rows
    layers = [layer for layer in getattr(model, "layers", None) or ()
              if type(layer).__name__ not in _BEFORE_CROP]
    if not layers or type(layers[0]).__name__ != "Cropping2D" or getattr(
            layers[0], "data_format", "channels_last") != "channels_last":
        return None
    (top, bottom), _ = layers[0].cropping
    first, end = int(top), IMAGE_SHAPE[0] - int(bottom)
    return (first, end) if 0 <= first < end <= IMAGE_SHAPE[0] else None
