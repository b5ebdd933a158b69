#include "experiments/heap_retention.h"

#include <unistd.h>

#include <algorithm>
#include <cstddef>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>

#if defined(__GLIBC__)
#include <gnu/libc-version.h>
#include <malloc.h>
#endif

namespace artex {

bool RetainFreedHeap(int megabytes) {
  if (megabytes <= 0) return false;
#if defined(__GLIBC__)
  constexpr int kMb = 1 << 20;
  // 32 MB: glibc refuses an mmap threshold above half its 64 MB heap size on 64-bit systems.
  const int mmap_threshold = 32 * kMb;
  const long long trim = static_cast<long long>(megabytes) * kMb;
  const int trim_threshold = static_cast<int>(std::min<long long>(trim, 1 << 30));
  const int top_pad = std::min(megabytes, 64) * kMb;
  // mallopt returns 1 on success; the sanitizers' allocators return 0 for every call.
  return mallopt(M_MMAP_THRESHOLD, mmap_threshold) == 1 &&
         mallopt(M_TRIM_THRESHOLD, trim_threshold) == 1 && mallopt(M_TOP_PAD, top_pad) == 1;
#else
  return false;
#endif
}

bool LimitHeapArenas(int arenas) {
  if (arenas <= 0) return false;
#if defined(__GLIBC__)
  return mallopt(M_ARENA_MAX, arenas) == 1;
#else
  return false;
#endif
}

namespace {

char** program_arguments = nullptr;

// True when built with AddressSanitizer or ThreadSanitizer (their allocators replace glibc's).
constexpr bool kSanitized =
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
    true;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer)
    true;
#else
    false;
#endif
#else
    false;
#endif

// The kernel's transparent huge page mode: the bracketed word of
// /sys/kernel/mm/transparent_hugepage/enabled ("always [madvise] never"), "" when unknown.
std::string TransparentHugePageMode() {
  std::ifstream in("/sys/kernel/mm/transparent_hugepage/enabled");
  std::string line;
  if (!std::getline(in, line)) return "";
  const std::size_t open = line.find('['), close = line.find(']');
  if (open == std::string::npos || close == std::string::npos || close < open) return "";
  return line.substr(open + 1, close - open - 1);
}

constexpr const char* kTunable = "glibc.malloc.hugetlb";

// glibc 2.35 or later (the tunable's first release) and not under a sanitizer.
bool GlibcHasHugeTlbTunable() {
#if defined(__GLIBC__)
  if (kSanitized) return false;
  int major = 0, minor = 0;
  return std::sscanf(gnu_get_libc_version(), "%d.%d", &major, &minor) == 2 &&
         major * 1000 + minor >= 2035;
#else
  return false;
#endif
}

}  // namespace

void RememberProgramArguments(char** argv) { program_arguments = argv; }
char** ProgramArguments() { return program_arguments; }

bool HugePageHeapAvailable() {
  const std::string mode = TransparentHugePageMode();
  return mode == "always" || (mode == "madvise" && GlibcHasHugeTlbTunable());
}

bool HugePageHeapActive() {
  const std::string mode = TransparentHugePageMode();
  if (mode == "always") return true;
  const char* tunables = std::getenv("GLIBC_TUNABLES");
  return mode == "madvise" && GlibcHasHugeTlbTunable() && tunables != nullptr &&
         (std::string(tunables).find(std::string(kTunable) + "=1") != std::string::npos ||
          std::string(tunables).find(std::string(kTunable) + "=2") != std::string::npos);
}

void ReexecWithHugePageHeap(char** argv) {
#if defined(__GLIBC__)
  if (argv == nullptr || argv[0] == nullptr || !GlibcHasHugeTlbTunable()) return;
  const char* tunables = std::getenv("GLIBC_TUNABLES");
  const bool had_tunables = tunables != nullptr;
  const std::string current = had_tunables ? tunables : "";  // a copy: setenv may replace it
  if (current.find(kTunable) != std::string::npos) return;  // set (by us or the user)
  if (TransparentHugePageMode() != "madvise") return;
  const std::string value = current.empty() ? std::string(kTunable) + "=1"
                                            : current + ":" + kTunable + "=1";
  if (setenv("GLIBC_TUNABLES", value.c_str(), 1) != 0) return;
  std::fflush(stdout);
  std::fflush(stderr);
  // The program's own path, so that the process keeps its name (ps, top: /proc/self/exe would
  // name it "exe"); /proc/self/exe itself when the path is unknown or the file was replaced.
  char path[4096];
  const ssize_t n = readlink("/proc/self/exe", path, sizeof(path) - 1);
  std::string program = "/proc/self/exe";
  if (n > 0) {
    path[n] = '\0';
    if (access(path, X_OK) == 0) program = path;
  }
  execv(program.c_str(), argv);
  // The exec failed: carry on with the ordinary heap, the environment as it was.
  if (had_tunables) {
    setenv("GLIBC_TUNABLES", current.c_str(), 1);
  } else {
    unsetenv("GLIBC_TUNABLES");
  }
#else
  (void)argv;
#endif
}

}  // namespace artex
