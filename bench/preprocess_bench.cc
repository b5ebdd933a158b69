// placeholder: filled in by its owner
#include <benchmark/benchmark.h>
