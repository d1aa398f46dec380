// Programmer-error assertions (tier 1 of STYLE.md): always on, abort with file, line and condition.
#pragma once

#include <cstdio>
#include <cstdlib>

#define VELLUM_DEMAND(condition)                                                                 \
  do {                                                                                           \
    if (!(condition)) {                                                                          \
      std::fprintf(stderr, "%s:%d: VELLUM_DEMAND failed: %s\n", __FILE__, __LINE__, #condition); \
      std::abort();                                                                              \
    }                                                                                            \
  } while (0)
