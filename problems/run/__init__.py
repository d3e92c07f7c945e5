"""The run contract: the scene registry's types, parameter dataclasses and their
validation, the run context, results.json, field output, checkpoints, sweeps and
benchmarks. Nothing here knows a model."""
