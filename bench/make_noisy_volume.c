/* The temporary-disk bench's noisy volume at sizes Python cannot reach in
 * time (2048^3 u16 = 16 GiB): the same scene as make_noisy_volume.py (a ball
 * of 300 -> 2000 -> 3500 in air, rings at 0.4 n and 0.2 n) with Gaussian
 * noise of sigma 20 on every voxel, from a fixed-seed generator (not the
 * same values as the Python script, the same statistics).
 * Build: cc -O2 -o make_noisy_volume bench/make_noisy_volume.c -lm
 * Usage: make_noisy_volume N OUT.raw */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>

static uint64_t state = 0x9E3779B97F4A7C15ull;
static uint64_t next(void) { /* xorshift64* */
  state ^= state >> 12, state ^= state << 25, state ^= state >> 27;
  return state * 0x2545F4914F6CDD1Dull;
}

int main(int argc, char** argv) {
  if (argc != 3) return fprintf(stderr, "usage: %s N OUT.raw\n", argv[0]), 2;
  const long n = atol(argv[1]);
  FILE* out = fopen(argv[2], "wb");
  if (n <= 0 || !out) return fprintf(stderr, "%s: cannot write\n", argv[2]), 1;
  static int16_t noise[65536];
  for (int i = 0; i < 65536; i += 2) { /* Box-Muller, sigma 20 */
    const double u = ((next() >> 11) + 1.0) / 9007199254740993.0, v = (next() >> 11) / 9007199254740992.0;
    const double r = 20.0 * sqrt(-2.0 * log(u));
    noise[i] = (int16_t)lrint(r * cos(2 * M_PI * v)), noise[i + 1] = (int16_t)lrint(r * sin(2 * M_PI * v));
  }
  uint16_t* plane = malloc(2 * n * n);
  const double c = (n - 1) / 2.0, outer = 0.4 * n, inner = 0.2 * n;
  for (long z = 0; z < n; ++z) {
    for (long y = 0; y < n; ++y)
      for (long x = 0; x < n; x += 4) {
        const uint64_t bits = next();
        for (long d = 0; d < 4 && x + d < n; ++d) {
          const double r = sqrt((x + d - c) * (x + d - c) + (y - c) * (y - c) + (z - c) * (z - c));
          const int base = r > outer ? 300 : r > inner ? 2000 : 3500;
          plane[y * n + x + d] = (uint16_t)(base + noise[(bits >> (16 * d)) & 0xFFFF]);
        }
      }
    if (fwrite(plane, 2, n * n, out) != (size_t)(n * n)) return fprintf(stderr, "%s: write failed\n", argv[2]), 1;
  }
  return fclose(out) != 0;
}
