// OpenBLAS 0.3.21 predates Zen 5 and picks its "Haswell" kernels on this CPU; with
// OPENBLAS_CORETYPE=SkylakeX it runs 1.6-1.8x faster (toolchain.md 4b). The variable is read when
// the library loads, before main(), so a program that wants it re-executes itself once with it
// set. Only when the CPU has the AVX-512 subsets those kernels use, and the user has not chosen.
#pragma once

namespace btfc {

// Call first thing in main(). Returns normally when nothing is to be done or exec fails.
void reexec_for_openblas(int argc, char** argv);

}  // namespace btfc
