"""``python -m pfault SCENE.opts [-option value ...]``: runs a scene (a PETSc options file).

petsc4py.init() must see the options before PETSc is imported, so the scene file is turned into
``-options_file SCENE.opts`` ahead of the command-line options, which therefore override it.
"""

import os
import sys

USAGE = "usage: mpirun -n N python -m pfault SCENE.opts [-option value ...]   (python -m pfault -help lists options)"


def _args(argv):
    rest = list(argv[1:])
    scene = None
    if rest and not rest[0].startswith("-"):
        scene = rest.pop(0)
    return scene, rest


def main(argv=None):
    argv = list(sys.argv if argv is None else argv)
    scene, rest = _args(argv)
    wants_help = "-help" in rest or "--help" in rest or "-h" in rest
    if scene is None and wants_help:
        from pfault.options import help_text
        print(USAGE)
        print(help_text())
        return 0
    if scene is None:
        sys.stderr.write(f"pfault: error: no scene file given\n{USAGE}\n")
        return 2
    if not os.path.isfile(scene):
        sys.stderr.write(f"pfault: error: scene file '{scene}' not found (give a PETSc options file such as "
                         f"config/demo.opts)\n")
        return 2
    rest = ["-help" if a in ("--help", "-h") else a for a in rest]
    import petsc4py
    petsc4py.init([argv[0], "-options_file", scene] + rest)
    from pfault import cli
    return cli.main(scene, argv)


if __name__ == "__main__":
    sys.exit(main())
