"""The steering model's contract: output names, model files (checked, bounded, loaded, exported),
the rows a model looks at, the driving settings stored with it, and the tiny test models."""
