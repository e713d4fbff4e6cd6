"""The platforms the native edition builds for, and the zig target of each binary."""
from __future__ import annotations

from dataclasses import dataclass

from harness.fmu_build.toolchain import NativeBuildError


@dataclass(frozen=True)
class Target:
    platform: str       # the FMI 2.0 platform this binary belongs to
    zig: str            # zig target triple
    fmi3_folder: str    # FMI 3.0 platform folder
    extension: str


TARGETS = (
    Target("linux64", "x86_64-linux-gnu.2.17", "x86_64-linux", ".so"),
    Target("win64", "x86_64-windows-gnu", "x86_64-windows", ".dll"),
    Target("darwin64", "x86_64-macos.10.13", "x86_64-darwin", ".dylib"),
    Target("darwin64", "aarch64-macos.11.0", "aarch64-darwin", ".dylib"),
    # FMI 2.0 standardises no folder for ARM Linux (linux64 is x86-64): the FMI 3.0 name serves both
    Target("aarch64-linux", "aarch64-linux-gnu.2.17", "aarch64-linux", ".so"),
)
PLATFORMS = ("linux64", "win64", "darwin64", "aarch64-linux")


def selected_targets(platforms) -> tuple[Target, ...]:
    unknown = set(platforms) - set(PLATFORMS)
    if unknown:
        raise NativeBuildError(f"unknown platform(s) {sorted(unknown)}; valid: {list(PLATFORMS)}")
    return tuple(t for t in TARGETS if t.platform in platforms)

