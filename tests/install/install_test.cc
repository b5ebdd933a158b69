// `cmake --install` of this build into a temporary prefix, then a tiny external CMake project
// (tests/install/consumer) configured with find_package(artex), built against the installed
// tree and run; also imports the installed Python package when it was built.
#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>

namespace {

namespace fs = std::filesystem;

// Runs `command` through the shell, returns its exit status and its output (stdout+stderr).
int RunCommand(const std::string& command, std::string* output) {
  output->clear();
  FILE* pipe = popen((command + " 2>&1").c_str(), "r");
  if (!pipe) return -1;
  char buffer[4096];
  while (fgets(buffer, sizeof(buffer), pipe)) *output += buffer;
  const int status = pclose(pipe);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

std::string Quoted(const fs::path& p) { return "'" + p.string() + "'"; }

TEST(InstallTest, ExternalProjectBuildsAndRunsAgainstInstalledTree) {
  const fs::path root =
      fs::temp_directory_path() / ("artex-install-test-" + std::to_string(getpid()));
  fs::remove_all(root);
  const fs::path prefix = root / "prefix";
  std::string out;
  ASSERT_EQ(RunCommand("cmake --install " + Quoted(ARTEX_BUILD_DIR) + " --prefix " + Quoted(prefix),
                       &out),
            0)
      << out;
  EXPECT_TRUE(fs::exists(prefix / "lib" / "cmake" / "artex" / "artexConfig.cmake"));
  EXPECT_TRUE(fs::exists(prefix / "include" / "artex" / "models" / "skinning.h"));
  EXPECT_TRUE(fs::exists(prefix / "lib" / "libartex_solvers.a"));
  EXPECT_TRUE(fs::exists(prefix / "bin" / "artex"));

  const fs::path build = root / "consumer-build";
  ASSERT_EQ(RunCommand("cmake -S " +
                           Quoted(fs::path(ARTEX_SOURCE_DIR) / "tests" / "install" / "consumer") +
                           " -B " + Quoted(build) + " -G Ninja -DCMAKE_BUILD_TYPE=Release" +
                           " -DCMAKE_PREFIX_PATH=" + Quoted(prefix),
                       &out),
            0)
      << out;
  ASSERT_EQ(RunCommand("cmake --build " + Quoted(build), &out), 0) << out;
  ASSERT_EQ(RunCommand(Quoted(build / "artex_consumer"), &out), 0) << out;
  EXPECT_NE(out.find("artex consumer:"), std::string::npos) << out;
  EXPECT_NE(out.find("converged"), std::string::npos) << out;

  // The installed tool runs from the prefix.
  ASSERT_EQ(RunCommand(Quoted(prefix / "bin" / "artex") + " --version", &out), 0) << out;

  const std::string python_dir = ARTEX_PYTHON_INSTALL_DIR;
  if (!python_dir.empty()) {
    ASSERT_EQ(RunCommand("cd / && PYTHONPATH=" + Quoted(prefix / python_dir) + " " + ARTEX_PYTHON +
                             " -c 'import artex; print(artex.__file__)'",
                         &out),
              0)
        << out;
    EXPECT_NE(out.find(prefix.string()), std::string::npos) << out;
  }
  fs::remove_all(root);
}

// Configures the source tree into a fresh folder with `options` (no tests, benchmarks or Python
// module: only the configure step's checks matter); its output in *out, its exit status returned.
int ConfigureWith(const std::string& name, const std::string& options, std::string* out) {
  const fs::path build =
      fs::temp_directory_path() / ("artex-" + name + "-test-" + std::to_string(getpid()));
  fs::remove_all(build);
  const std::string configure =
      "cmake -S " + Quoted(ARTEX_SOURCE_DIR) + " -B " + Quoted(build) +
      " -G Ninja -DCMAKE_BUILD_TYPE=Release -DARTEX_BUILD_TESTS=OFF -DARTEX_BUILD_BENCH=OFF"
      " -DARTEX_BUILD_PYTHON=OFF " +
      options;
  const int status = RunCommand(configure, out);
  fs::remove_all(build);
  return status;
}

// With the static libceres.a (compiled for plain x86-64), flags that make Eigen use AVX are
// refused at configure time, naming the flags and the ways out: Eigen compiled for AVX allocates
// its matrices with another allocator than the library's copy of the same functions
// (docs/install.md, "Instruction set and Ceres").
TEST(InstallTest, ConfigureRefusesAvxFlagsWithStaticCeres) {
  std::string out;
  EXPECT_NE(ConfigureWith("avx-static", "-DARTEX_CERES_SHARED=OFF -DCMAKE_CXX_FLAGS=-mavx2", &out),
            0)
      << out;
  EXPECT_NE(out.find("compile for AVX"), std::string::npos) << out;
  EXPECT_NE(out.find("-mavx2"), std::string::npos) << out;
  EXPECT_NE(out.find("ARTEX_CERES_SHARED"), std::string::npos) << out;
  EXPECT_NE(out.find("ARTEX_ALLOW_AVX_EIGEN"), std::string::npos) << out;
}

// ARTEX_ARCH=auto never picks AVX with the static Ceres; a -march given by hand is refused there.
TEST(InstallTest, AutoArchKeepsPlainX86WithStaticCeres) {
  std::string out;
  EXPECT_EQ(ConfigureWith("arch-static", "-DARTEX_CERES_SHARED=OFF", &out), 0) << out;
  EXPECT_NE(out.find("compiling for the compiler's default instruction set"), std::string::npos)
      << out;
  EXPECT_NE(ConfigureWith("arch-static-v3", "-DARTEX_CERES_SHARED=OFF -DARTEX_ARCH=x86-64-v3",
                          &out),
            0)
      << out;
  EXPECT_NE(out.find("-march=x86-64-v3"), std::string::npos) << out;
}

// An ARTEX_ARCH the compiler does not know stops the configure step, naming the value.
// A fresh configure with ARTEX_ARCH=auto and the shared Ceres compiles for x86-64-v3 exactly
// when this machine's CPU runs it (the probe once compiled half a program and never did).
TEST(InstallTest, AutoArchPicksX86V3WhereTheCpuRunsIt) {
  if (!fs::exists("/usr/lib/x86_64-linux-gnu/libceres.so"))
    GTEST_SKIP() << "no shared libceres.so on this machine";
  std::string out;
  ASSERT_EQ(ConfigureWith("arch-auto", "", &out), 0) << out;
  __builtin_cpu_init();
  const bool v3 = __builtin_cpu_supports("x86-64-v3");
  EXPECT_EQ(out.find("artex: compiling for -march=x86-64-v3") != std::string::npos, v3) << out;
  EXPECT_EQ(out.find("Unknown argument"), std::string::npos) << out;
}

TEST(InstallTest, ConfigureRejectsAnUnknownArch) {
  std::string out;
  EXPECT_NE(ConfigureWith("arch-unknown", "-DARTEX_ARCH=no-such-cpu", &out), 0) << out;
  EXPECT_NE(out.find("ARTEX_ARCH: expected auto"), std::string::npos) << out;
  EXPECT_NE(out.find("\"no-such-cpu\""), std::string::npos) << out;
}

// With Ceres's shared library (the default where Debian ships it) the same flags configure:
// libceres.so keeps its Eigen code to itself.
TEST(InstallTest, ConfigureAcceptsAvxFlagsWithSharedCeres) {
  if (!fs::exists("/usr/lib/x86_64-linux-gnu/libceres.so"))
    GTEST_SKIP() << "no shared libceres.so on this machine";
  std::string out;
  EXPECT_EQ(ConfigureWith("avx-shared", "-DCMAKE_CXX_FLAGS=-mavx2", &out), 0) << out;
  EXPECT_EQ(out.find("compile for AVX"), std::string::npos) << out;
}

}  // namespace
