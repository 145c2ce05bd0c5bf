"""Bring your own robot: import a URDF, xacro or MJCF description (``robogest robots import``).

Modules, in the order an import runs: :mod:`.description` reads the file (xacro expanded, repairs made, every read
confined to the description's tree), :mod:`.meshes` copies and converts its meshes, :mod:`.parts` finds legs, waist,
arms, head and fingers from the kinematic tree, :mod:`.model` adds what robogest needs to the MJCF, :mod:`.write`
writes the YAML and publishes everything at once; :mod:`.build` runs them. It sits above :mod:`robogest.retarget`:
the rest pose is the IK's image of a person standing at rest.
"""

from robogest.tools.importer.build import ImportResult, import_description

__all__ = ["ImportResult", "import_description"]
