// Where the tests find the checkout and the shared data: BTFC_SOURCE_DIR (the source tree) and
// BTFC_DATA_DIR (../shared/data beside it), as C strings.
//
// They are variables defined in the build tree's generated test_paths.cpp (tests/CMakeLists.txt)
// rather than -D definitions, so no test file's command line holds the checkout's absolute path:
// a fresh clone elsewhere compiles every test file exactly as before and ccache (scripts/build.sh)
// serves them all; only the one generated file differs.
#pragma once

extern const char* const btfc_test_source_dir;
extern const char* const btfc_test_data_dir;

#define BTFC_SOURCE_DIR btfc_test_source_dir
#define BTFC_DATA_DIR btfc_test_data_dir
