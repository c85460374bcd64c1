#pragma once
// FUZZ_CHECK(condition): a property every input must keep. A violation aborts, which libFuzzer
// reports as a crash and saves the input (crash-<sha1>) to reproduce it.

#include <cstdio>
#include <cstdlib>

#define FUZZ_CHECK(condition)                                                          \
  do {                                                                                 \
    if (!(condition)) {                                                                \
      std::fprintf(stderr, "%s:%d: FUZZ_CHECK failed: %s\n", __FILE__, __LINE__, #condition); \
      std::abort();                                                                    \
    }                                                                                  \
  } while (false)
