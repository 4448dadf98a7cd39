#pragma once
// PREVIZ_WIDE before a function: it is compiled twice, for AVX2 (Intel Haswell 2013, AMD
// Excavator 2015 and later) and for the baseline x86-64 the build targets (SSE2), and the loader
// picks the version this CPU runs (GCC's target_clones: an ifunc, resolved once at start-up).
// For the live frame's per-pixel and per-cell loops: 256-bit vectors where the vectoriser finds
// them, VEX encoding (no register copies), POPCNT and LZCNT as instructions.
//  - Only the function and what is inlined into it are compiled twice: a callee that is not
//    inlined runs its one (baseline) version. GCC inlines less into the versions than into a
//    plain function, so hot helpers are marked [[gnu::always_inline]].
//  - The two versions give the same bits: the libraries that use PREVIZ_WIDE are built with
//    -ffp-contract=off (no fused multiply-add in either; the vectoriser does not reassociate
//    without -ffast-math). tests/live/wide_test.sh runs previz on a CPU without AVX (qemu) and
//    compares every output byte with the native run's.
//  - Empty where it does not apply: other compilers (clang has no target_clones on templates),
//    other CPUs, a build whose baseline already has AVX2 (PREVIZ_NATIVE), or cmake
//    -DPREVIZ_WIDE=OFF (PREVIZ_NO_WIDE).
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && !defined(__AVX2__) && \
    !defined(PREVIZ_NO_WIDE)
#define PREVIZ_WIDE __attribute__((target_clones("avx2", "default")))
#define PREVIZ_WIDE_CLONES 1
#else
#define PREVIZ_WIDE
#define PREVIZ_WIDE_CLONES 0
#endif

namespace previz {
// The version PREVIZ_WIDE functions run in this process: "avx2", "baseline" (a CPU without AVX2:
// the loader's choice, made by the same test) or "off" (a build without the two versions).
inline const char* wideVersion() {
#if PREVIZ_WIDE_CLONES
  return __builtin_cpu_supports("avx2") ? "avx2" : "baseline";
#else
  return "off";
#endif
}
}  // namespace previz
