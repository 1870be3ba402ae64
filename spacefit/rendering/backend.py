"""Dr.Jit / Mitsuba start-up: the system libLLVM and the variant (llvm_ad_rgb or cuda_ad_rgb).

Dr.Jit's LLVM backend loads the system's libLLVM at run time. Debian 12's default libLLVM 15 aborts
at the first render ("LLVM ERROR: Cannot select: ... fminimum"), and so did 16 here; 19 works.
Unless the user has set ``DRJIT_LIBLLVM_PATH``, the newest libLLVM >= ``MIN_LLVM_MAJOR`` found is used. This module must be
imported before ``drjit``; the rendering package does so.
"""

from __future__ import annotations

import glob
import os
import re

MIN_LLVM_MAJOR = 19
LLVM_GLOBS = ("/usr/lib/x86_64-linux-gnu/libLLVM*.so*", "/usr/lib/aarch64-linux-gnu/libLLVM*.so*", "/usr/lib/llvm-*/lib/libLLVM*.so*")


def find_libllvm() -> tuple[str | None, int]:
    """Path and major version of the newest system libLLVM (None, 0 when there is none)."""
    best: tuple[str | None, int] = (None, 0)
    for pattern in LLVM_GLOBS:
        for path in glob.glob(pattern):
            match = re.search(r"libLLVM[-.](?:so\.)?(\d+)", os.path.basename(path))
            if match and int(match.group(1)) > best[1]:
                best = (path, int(match.group(1)))
    return best


def configure_llvm() -> None:
    """Point Dr.Jit at a libLLVM new enough for it (>= MIN_LLVM_MAJOR), unless ``DRJIT_LIBLLVM_PATH`` is set."""
    if "DRJIT_LIBLLVM_PATH" in os.environ:
        return
    path, major = find_libllvm()
    if path is not None and major >= MIN_LLVM_MAJOR:
        os.environ["DRJIT_LIBLLVM_PATH"] = path


configure_llvm()

import drjit as dr  # noqa: E402  (after configure_llvm, which must run first)
import mitsuba as mi  # noqa: E402

from spacefit.errors import InputError  # noqa: E402


def llvm_problem() -> str | None:
    """Why the LLVM backend cannot render here, or None when it can."""
    path, major = find_libllvm()
    if "DRJIT_LIBLLVM_PATH" not in os.environ and major < MIN_LLVM_MAJOR:
        found = f"found libLLVM {major} ({path})" if path else "found no libLLVM"
        return (
            f"Dr.Jit needs libLLVM >= {MIN_LLVM_MAJOR} on the CPU and {found}. "
            "Install it with: sudo apt-get update && sudo apt-get install -y libllvm19"
        )
    return None


def select_variant(requested: str = "auto") -> str:
    """Set and return the Mitsuba variant: cuda_ad_rgb when a CUDA GPU is usable, else llvm_ad_rgb."""
    if requested == "auto":
        requested = "cuda_ad_rgb" if dr.has_backend(dr.JitBackend.CUDA) else "llvm_ad_rgb"
    if requested.startswith("llvm") and (problem := llvm_problem()):
        raise InputError(problem)
    if requested.startswith("cuda") and not dr.has_backend(dr.JitBackend.CUDA):
        raise InputError("`render.variant` 'cuda_ad_rgb' needs an NVIDIA GPU with its driver, and none is usable here; "
                         "use 'auto' or 'llvm_ad_rgb'.")
    if requested not in mi.variants():
        raise InputError(f"`render.variant` {requested!r} is not built into this Mitsuba; it has {mi.variants()}.")
    if mi.variant() != requested:
        mi.set_variant(requested)
    return requested
