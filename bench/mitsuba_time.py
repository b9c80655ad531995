#!/usr/bin/env python3
"""Times Mitsuba 3's `llvm_ad_rgb` renders of a scene: one render to compile the kernels, then
RUNS timed renders (seeds 1..RUNS), each waited for (`dr.eval`, `dr.sync_thread`). Prints one
time in seconds per line.

    python3 bench/mitsuba_time.py SCENE.xml SPP [RUNS] [NAME=VALUE ...]

NAME=VALUE pairs set the scene's <default> parameters (as `snell render -D NAME=VALUE` does).
Needs `pip install mitsuba` and LLVM (`apt-get install libllvm19`); DRJIT_LIBLLVM_PATH defaults
to Debian's libLLVM 19.

MITSUBA_ISA=avx2 holds Dr.Jit's compiled kernels to AVX2 and eight lanes (`haswell`), where
they would otherwise use every instruction set of the CPU (sixteen AVX-512 lanes where it has
them); Embree, inside Mitsuba, keeps its own choice. It calls Dr.Jit's `jit_llvm_set_target`,
which the Python bindings do not expose, through ctypes, and fails if the library lacks it.
"""
import ctypes
import os
import sys
import time

os.environ.setdefault("DRJIT_LIBLLVM_PATH", "/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1")


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    path, spp = sys.argv[1], int(sys.argv[2])
    rest = sys.argv[3:]
    runs = int(rest.pop(0)) if rest and "=" not in rest[0] else 3
    params = dict(kv.split("=", 1) for kv in rest)
    import drjit as dr
    import mitsuba as mi

    mi.set_variant("llvm_ad_rgb")
    isa = os.environ.get("MITSUBA_ISA", "")
    if isa == "avx2":
        try:
            lib = ctypes.CDLL(os.path.join(os.path.dirname(dr.__file__), "libdrjit-core.so"))
            set_target = lib._Z19jit_llvm_set_targetPKcS0_j  # jit_llvm_set_target(cpu, features, width)
            # Read back after the call, so that a Dr.Jit that ignored it is not timed as if it had not.
            cpu, width = lib._Z19jit_llvm_target_cpuv, lib._Z21jit_llvm_vector_widthv
        except (OSError, AttributeError) as e:
            sys.exit(f"MITSUBA_ISA=avx2: cannot reach Dr.Jit's LLVM target functions ({e})")
        set_target.argtypes = [ctypes.c_char_p, ctypes.c_char_p, ctypes.c_uint32]
        set_target(b"haswell", b"+avx2,+fma,+f16c,+popcnt,+bmi,+bmi2,+lzcnt", 8)
        cpu.restype, width.restype = ctypes.c_char_p, ctypes.c_uint32
        if (cpu(), width()) != (b"haswell", 8):
            sys.exit(f"MITSUBA_ISA=avx2: Dr.Jit still targets {cpu()!r} with {width()} lanes")
    elif isa:
        sys.exit(f"MITSUBA_ISA={isa}: the only choice is avx2 (unset: every instruction set of the CPU)")
    scene = mi.load_file(path, **params)
    img = mi.render(scene, spp=spp)
    dr.eval(img)
    dr.sync_thread()
    for i in range(runs):
        t = time.perf_counter()
        img = mi.render(scene, spp=spp, seed=i + 1)
        dr.eval(img)
        dr.sync_thread()
        print(f"{time.perf_counter() - t:.3f}", flush=True)


if __name__ == "__main__":
    main()
