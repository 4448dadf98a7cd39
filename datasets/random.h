#pragma once
// Deterministic randomness for the synthetic studio. std::mt19937 is portable but the standard
// distributions are not (libstdc++ and libc++ draw differently), so takes would not be
// reproducible bit for bit across toolchains; these few lines are, everywhere.
#include <cmath>
#include <cstdint>

namespace previz::synth {

// SplitMix64 finaliser (Steele et al. 2014): a bijective 64-bit mix with full avalanche.
inline std::uint64_t mix64(std::uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

// Hash of a tuple of integers (order matters). Counter-based: the value for a key depends on
// the key only, never on how many values were drawn before, so threads cannot change it.
inline std::uint64_t hashKey(std::uint64_t a, std::uint64_t b = 0, std::uint64_t c = 0,
                             std::uint64_t d = 0, std::uint64_t e = 0) {
  std::uint64_t h = mix64(a);
  h = mix64(h ^ b);
  h = mix64(h ^ c);
  h = mix64(h ^ d);
  return mix64(h ^ e);
}

// Uniform in [0, 1) with 53 random bits.
inline double unitFromBits(std::uint64_t bits) {
  return static_cast<double>(bits >> 11) * (1.0 / 9007199254740992.0);
}

// Standard normal from one 64-bit key (Box–Muller on two derived uniforms).
inline double normalFromKey(std::uint64_t key) {
  const double u1 = 1.0 - unitFromBits(mix64(key));           // (0, 1]
  const double u2 = unitFromBits(mix64(key ^ 0xD1B54A32D192ED03ull));
  return std::sqrt(-2.0 * std::log(u1)) * std::cos(6.283185307179586 * u2);
}

// A small sequential generator for scene layout (camera placement, board paths).
class Rng {
 public:
  explicit Rng(std::uint64_t seed, std::uint64_t stream = 0) : state_(hashKey(seed, stream)) {}
  std::uint64_t next() {
    state_ += 0x9E3779B97F4A7C15ull;
    return mix64(state_);
  }
  double uniform() { return unitFromBits(next()); }
  double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }
  double normal() { return normalFromKey(next()); }

 private:
  std::uint64_t state_;
};

}  // namespace previz::synth
