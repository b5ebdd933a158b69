// The source of artex_test_pch (tests/CMakeLists.txt): the executable whose build compiles the
// test sources' precompiled headers once per build folder; it does nothing when run.
int main() { return 0; }
