"""The network: its layers, output shapes and parameter counts, read from ``model.keras``.
"""

from __future__ import annotations

import numpy as np

from clonedrive.report import formatting as fmt
from clonedrive.report.context import SECTION_TITLES, ReportContext
from clonedrive.report.document import Paragraph, Section, Table


def build(ctx: ReportContext) -> list[Section]:
    title = SECTION_TITLES["network"]
    train = ctx.parts.train_dir
    model_path = train / "model.keras" if train else None
    if model_path is None or not model_path.is_file():
        return ctx.missing(title, "No `model.keras`: network section skipped.")
    from clonedrive.base.keras_backend import import_keras
    from clonedrive.network.model_bounds import ModelBoundsError
    from clonedrive.network.model_file import check_keras_file

    try:
        check_keras_file(model_path)  # a shared run folder's model may ask for all the memory
    except ModelBoundsError as error:  # (a file that is no model fails as Keras would)
        return ctx.missing(title, f"`model.keras` refused: {error}")
    keras = import_keras()
    model = keras.saving.load_model(model_path, safe_mode=True, compile=False)
    rows = []
    for layer in model.layers:
        try:
            shape = fmt.shape(layer.output.shape)
        except (AttributeError, ValueError):
            shape = "?"
        rows.append((layer.name, type(layer).__name__, shape, f"{layer.count_params():,}"))
    total = model.count_params()
    trainable = sum(int(np.prod(w.shape)) for w in model.trainable_weights)
    rows.append(("total", "", "", f"{total:,}"))
    architecture = (ctx.train_config or {}).get("model", model.name)
    preprocessing = []
    for layer in model.layers:
        if layer.count_params() > 0:
            break
        if type(layer).__name__ != "InputLayer":
            preprocessing.append(f"{type(layer).__name__} `{layer.name}`")
    ctx.facts["params"] = total
    ctx.headline(
        f"Network: `{architecture}`, {len(model.layers)} layers, {total:,} parameters.")
    text = (f"The network is the `{architecture}` architecture (Keras model "
            f"`{model.name}`), read from `{fmt.relative(model_path, ctx.parts.run_dir)}`. It "
            f"takes the raw {fmt.shape(model.input_shape)} RGB camera frame and outputs one "
            "steering value. ")
    if preprocessing:
        text += ("Pre-processing is part of the model (" + ", ".join(preprocessing) + "), "
                 "so training and driving cannot prepare pictures differently. ")
    text += (f"It has **{total:,} parameters** ({trainable:,} trainable).")
    return [Section(title, blocks=[
        Paragraph(text),
        Table(("layer", "type", "output shape", "parameters"), tuple(rows), align="lllr",
              total_rows=(len(rows) - 1,)),
    ])]
