"""Where the shipped robot and cell models live, and how a Drake parser finds them.

The models ship as the resource package ``rtcohand_drake_models`` (the
``models/`` directory of the source tree); its ``package.xml`` names the same
package, so URLs such as
``package://rtcohand_drake_models/gen3/gen3_7dof.urdf`` resolve offline.
"""

from __future__ import annotations

import importlib
import importlib.resources
import pathlib

PACKAGE_NAME = "rtcohand_drake_models"

# Model URLs, relative to the package, for the station and the tests.
GEN3_URL = f"package://{PACKAGE_NAME}/gen3/gen3_7dof.urdf"
GRIPPER_URL = f"package://{PACKAGE_NAME}/robotiq_2f85/robotiq_2f85.sdf"
WORKPIECE_URL = f"package://{PACKAGE_NAME}/workpiece/workpiece.sdf"
TABLE_URL = f"package://{PACKAGE_NAME}/cell/table.sdf"
MOLD_URL = f"package://{PACKAGE_NAME}/cell/mold.sdf"
SAFETY_GLASS_URL = f"package://{PACKAGE_NAME}/cell/safety_glass.sdf"
INSPECTOR_URL = f"package://{PACKAGE_NAME}/cell/inspector.sdf"


def models_dir() -> pathlib.Path:
    """The directory holding ``package.xml`` and the model files."""
    try:
        return pathlib.Path(str(importlib.resources.files(PACKAGE_NAME)))
    except NotADirectoryError:
        # An editable install made before models/__init__.py existed maps the
        # package as a namespace whose path also holds a non-directory hook
        # entry, which importlib.resources rejects; its real directory is
        # still on __path__.
        for entry in importlib.import_module(PACKAGE_NAME).__path__:
            if (pathlib.Path(entry) / "package.xml").is_file():
                return pathlib.Path(entry)
        raise


def add_package(parser) -> None:
    """Registers ``rtcohand_drake_models`` on a pydrake ``Parser`` (idempotent)."""
    package_map = parser.package_map()
    if not package_map.Contains(PACKAGE_NAME):
        package_map.AddPackageXml(str(models_dir() / "package.xml"))


def policy_file_path(name: str | pathlib.Path) -> pathlib.Path:
    """A scenario's `policy.model`: a path as given when it exists or is absolute, else a file in models/."""
    path = pathlib.Path(name)
    return path if path.is_absolute() or path.exists() else models_dir() / path
