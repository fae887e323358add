"""Only one thing pyproject.toml cannot say: the OpenFOAM case templates live at the top of the
repository (templates/openfoam/, the project's layout) and ship in the wheel as package data
vcs/cfd/templates/openfoam/ (found by vcs.cfd.openfoam.template_dir())."""

import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py


class BuildPyWithTemplates(build_py):
    """build_py that also copies templates/openfoam into the built package."""

    def run(self):
        super().run()
        src = Path(__file__).resolve().parent / "templates" / "openfoam"
        dst = Path(self.build_lib) / "vcs" / "cfd" / "templates" / "openfoam"
        shutil.copytree(src, dst, dirs_exist_ok=True)


setup(cmdclass={"build_py": BuildPyWithTemplates})
