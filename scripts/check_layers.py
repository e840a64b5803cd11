#!/usr/bin/env python3
"""Fails on an #include that crosses btfc's layers the wrong way (docs/ARCHITECTURE.md).

Usage: check_layers.py [SOURCE_DIR]      (ctest `layers`; exit 1 and one line per bad edge)

Layers, lowest first; a file may include its own layer and the ones below:
  core/             data model, numerics, containers, descriptions (no file format, no codec)
  codecs/*.h|cpp    the codec framework (Codec, Model, registry, measure, render, GPU bundle)
  codecs/<name>/    one codec: core/, the framework, kernels/ and its own folder only: never
                    another codec, never formats/ (codecs know no file format)
  formats/          readers, writers, exporters' file side; may include the codecs' public
                    headers (codecs/*.h and codecs/<name>/<name>.h), not their internals
  cli/, mpi/        the programs: anything below, not each other
  python/           the Python module: anything below cli/ and mpi/ (it is a program too)
  bench/, tests/    anything
OpenCL headers (<CL/...>) only in core/cl_api.h, and that only in the runtime's device half, so
everything else builds without OpenCL (BTFC_OPENCL=OFF).
The registry (codecs/registry.cpp) is the one framework file that includes codecs' main headers.
"""
import os
import re
import sys

INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"', re.M)
OPENCL_HEADER = re.compile(r'^\s*#\s*include\s+[<"]CL/', re.M)
# OpenCL is optional and dlopen()ed (docs/ARCHITECTURE.md): only the runtime's API table includes
# an OpenCL header, and only the runtime's device half includes that table.
OPENCL_HEADER_FILES = ("core/cl_api.h",)
OPENCL_API_USERS = ("core/cl_api.cpp", "core/cl_device.cpp")
SOURCES = (".h", ".cpp", ".cl")


def layer_of(path):
    """(layer, detail) of a repository-relative path."""
    parts = path.split("/")
    top = parts[0]
    if top == "codecs":
        if len(parts) == 2:
            return "framework", None
        return "codec", parts[1]
    return top, None


def allowed(src, dst):
    """None when src may include dst, else the rule it breaks."""
    sl, scodec = layer_of(src)
    dl, dcodec = layer_of(dst)
    if dl not in ("core", "framework", "codec", "formats", "kernels", "cli", "mpi", "python", "tests", "bench"):
        return None  # generated files (build/) and system-like paths are not ours to rule
    if sl in ("bench", "tests"):
        return None
    if sl == "core":
        if dl in ("core", "kernels"):
            return None
        return "core/ includes only core/ (and kernels/ shared structs)"
    if sl == "framework":
        if dl in ("core", "framework", "kernels"):
            return None
        if dl == "codec" and src == "codecs/registry.cpp" and dst == f"codecs/{dcodec}/{dcodec}.h":
            return None
        return "the codec framework (codecs/*.h, *.cpp) includes core/ and itself; only codecs/registry.cpp names codecs"
    if sl == "codec":
        if dl in ("core", "framework", "kernels"):
            return None
        if dl == "codec" and dcodec == scodec:
            return None
        if dl == "codec":
            return f"codec {scodec} includes codec {dcodec}: shared numerics belong in core/"
        return f"codec {scodec} includes {dl}/: codecs know no file format (move the I/O to formats/)"
    if sl == "formats":
        if dl in ("core", "framework", "kernels", "formats"):
            return None
        if dl == "codec" and dst == f"codecs/{dcodec}/{dcodec}.h":
            return None
        if dl == "codec":
            return f"formats/ includes codec {dcodec}'s internals ({dst}): only its main header codecs/{dcodec}/{dcodec}.h"
        return f"formats/ includes {dl}/"
    if sl == "cli":
        return None if dl != "mpi" else "cli/ includes mpi/"
    if sl == "mpi":
        return None if dl != "cli" else "mpi/ includes cli/"
    if sl == "python":
        return None if dl not in ("cli", "mpi") else f"python/ includes {dl}/: the module calls the libraries, not a program"
    if sl == "kernels":
        return None if dl == "kernels" else "kernels/ include only kernels/"
    return None


def main():
    root = os.path.abspath(sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(__file__), ".."))
    bad = []
    checked = 0
    for top in ("core", "codecs", "formats", "cli", "mpi", "python", "kernels"):
        for dirpath, _, files in os.walk(os.path.join(root, top)):
            for f in sorted(files):
                if not f.endswith(SOURCES):
                    continue
                src = os.path.relpath(os.path.join(dirpath, f), root)
                with open(os.path.join(root, src), encoding="utf-8") as fh:
                    text = fh.read()
                if OPENCL_HEADER.search(text) and src not in OPENCL_HEADER_FILES:
                    bad.append(f"{src}: includes an OpenCL header: only core/cl_api.h may (use core/cl_runtime.h)")
                for m in INCLUDE.finditer(text):
                    dst = m.group(1)
                    if "/" not in dst:
                        continue  # same-folder or generated includes
                    checked += 1
                    why = allowed(src, dst)
                    if dst == "core/cl_api.h" and src not in OPENCL_API_USERS:
                        why = "core/cl_api.h (the dlopen()ed OpenCL table) is the runtime's own: use core/cl_runtime.h"
                    if why:
                        bad.append(f"{src}: #include \"{dst}\": {why}")
                if "../shared/" in text:
                    bad.append(f"{src}: refers to ../shared/ (outside the repository): cite the paper or document instead")
    for b in bad:
        print(b)
    print(f"check_layers: {checked} includes checked, {len(bad)} forbidden", file=sys.stderr)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
