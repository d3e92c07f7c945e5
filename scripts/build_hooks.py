"""setuptools commands (pyproject.toml, ``[tool.setuptools.cmdclass]``): the wheel and the
editable install both put ``eyemech-import-order.pth`` into site-packages, so that
``import dolfinx`` works in every Python of the environment (:mod:`import_order`)."""

from __future__ import annotations

from pathlib import Path

from setuptools.command.build_py import build_py
from setuptools.command.editable_wheel import editable_wheel

PTH_NAME = "eyemech-import-order.pth"
# one line: site.py executes a .pth line that starts with "import"
PTH_LINE = "import eyemech.scripts.import_order as _order; _order.install()\n"


class BuildPy(build_py):
    """The regular wheel: the .pth beside the packages, at the root of site-packages."""

    def run(self) -> None:
        super().run()
        target = Path(self.build_lib) / PTH_NAME
        target.write_text(PTH_LINE)

    def get_outputs(self, include_bytecode: bool = True) -> list[str]:
        return [*super().get_outputs(include_bytecode), str(Path(self.build_lib) / PTH_NAME)]


class EditableWheel(editable_wheel):
    """``pip install -e``: setuptools' editable wheel holds its own .pth and finder (its
    "strategy"); ours is written beside them."""

    def _select_strategy(self, name, tag, build_lib):
        return _WithPth(super()._select_strategy(name, tag, build_lib))


class _WithPth:
    """An editable strategy that also writes :data:`PTH_NAME` into the wheel."""

    def __init__(self, strategy) -> None:
        self.strategy = strategy

    def __call__(self, wheel, files, mapping) -> None:
        self.strategy(wheel, files, mapping)
        wheel.writestr(PTH_NAME, PTH_LINE)

    def __enter__(self):
        self.strategy.__enter__()
        return self

    def __exit__(self, *exc):
        return self.strategy.__exit__(*exc)
