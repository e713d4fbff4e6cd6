"""Build every FMU of the project into build/fmus/: the command (its code: harness/fmu_build/).

    python build_fmu.py                     # build the FMUs whose sources changed (both editions with zig)
    python build_fmu.py --force             # rebuild all
    python build_fmu.py --edition native --targets linux64   # the native edition, some platforms only
    python build_fmu.py --docs              # also rewrite the generated tables of docs/
"""
import sys

from harness.fmu_build.builder import main

if __name__ == "__main__":
    sys.exit(main())
