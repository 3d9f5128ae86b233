"""Only a build hook; the project metadata lives in pyproject.toml.

The shipped hand registry (``hand_specs/``) and policies (``policies/``) stay top-level folders of the repository
(one hand, one folder; one policy, one folder). A wheel carries them as package data: ``build_py`` copies them to
``dgz_cli/shipped/`` in the build tree, where :func:`dgz_cli.spec.catalog.specs_dir` / ``policies_dir`` look
first. An editable install reads them from the checkout instead.
"""

import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

HERE = Path(__file__).resolve().parent
SHIPPED = ("hand_specs", "policies")


class BuildPyWithShipped(build_py):
    def run(self):
        super().run()
        if getattr(self, "editable_mode", False):
            return
        for name in SHIPPED:
            src = HERE / name
            if not src.is_dir():  # building from an sdist that lacks them would ship a wheel without hands
                raise SystemExit(f"{src} is missing: build from a checkout or an sdist made by `python -m build`")
            dst = Path(self.build_lib) / "dgz_cli" / "shipped" / name
            shutil.copytree(src, dst, dirs_exist_ok=True,
                            ignore=shutil.ignore_patterns("__pycache__", "*.pyc", ".*", "runs"))


setup(cmdclass={"build_py": BuildPyWithShipped})
