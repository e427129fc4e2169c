#pragma once
// A temporary directory of the running test's own.

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <string>

namespace pumptherm::test_files {

/// `<tmp>/<prefix>_<test name>_<pid>`, created: CTest runs a file's tests in parallel, and tests
/// sharing one directory read each other's files.
inline std::string TestTempDir(const std::string& prefix) {
  const auto* info = testing::UnitTest::GetInstance()->current_test_info();
  const auto d =
      std::filesystem::temp_directory_path() /
      (prefix + "_" + (info != nullptr ? info->name() : "none") + "_" + std::to_string(getpid()));
  std::filesystem::create_directories(d);
  return d.string();
}

}  // namespace pumptherm::test_files
