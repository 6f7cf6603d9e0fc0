"""Whether HikingEnv compiles what a step and a reset derive from the physics
(``env.compile``), and the compiled or eager functions it then calls."""

from __future__ import annotations

from collections.abc import Callable

import torch

# env.compile=null compiles from this many robots up: there the graphs' 4-15 s of compiling
# pay back within a minute (bench_contacts.md), and small test envs stay eager
COMPILE_MIN_ENVS = 64


def derivations(step: Callable, reset: Callable, setting: bool | None, device: torch.device,
                num_envs: int) -> tuple[Callable, Callable]:
    """``(step, reset)`` as they are, or each as one ``torch.compile`` graph (fullgraph: a
    term that breaks the graph fails at the first step, not as a silent slowdown)."""
    if not wants_compile(setting, device, num_envs):
        return step, reset
    return (torch.compile(step, dynamic=False, fullgraph=True),
            torch.compile(reset, dynamic=False, fullgraph=True))


def wants_compile(setting: bool | None, device: torch.device, num_envs: int) -> bool:
    """Whether the env compiles its derivations: ``env.compile`` true (refused at once where
    no C++ compiler works) or false; None: on the CPU with a compiler, N >= COMPILE_MIN_ENVS."""
    cpu = torch.device(device).type == "cpu"
    if setting is not None:
        if setting and cpu and (err := compiler_error()):
            raise RuntimeError(f"env.compile=true on the CPU needs a C++ compiler for "
                               f"torch.compile ({err}); install g++ (or set CXX) or run with "
                               "env.compile=false")
        return bool(setting)
    return cpu and num_envs >= COMPILE_MIN_ENVS and compiler_error() is None


def compiler_error() -> str | None:
    """Why torch.compile cannot build C++ kernels here (None: it can)."""
    from torch._inductor.cpp_builder import get_cpp_compiler

    try:
        get_cpp_compiler()
    except Exception as err:
        return str(err)
    return None
