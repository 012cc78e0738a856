// A fresh folder per test for the test programs that write files: <temp>/<prefix><test name>,
// emptied before the test. Include as "../support/temp_dir.h".
#pragma once

#include <gtest/gtest.h>

#include <filesystem>
#include <string>

namespace deform::testing {

inline std::filesystem::path freshTestDir(const std::string& prefix) {
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() /
      (prefix + ::testing::UnitTest::GetInstance()->current_test_info()->name());
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

}  // namespace deform::testing
