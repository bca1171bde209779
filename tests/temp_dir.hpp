#pragma once
// A scratch folder per test (process id, suite and test name), removed afterwards.
#include <gtest/gtest.h>

#include <filesystem>
#include <string>
#include <unistd.h>

namespace demcal::test {

struct TempDir {
  std::filesystem::path path;
  TempDir() {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    path = std::filesystem::temp_directory_path() /
           ("demcal-test-" + std::to_string(getpid()) + "-" + info->test_suite_name() + "-" + info->name());
    std::filesystem::remove_all(path);
    std::filesystem::create_directories(path);
  }
  ~TempDir() { std::filesystem::remove_all(path); }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  std::string file(const std::string& n) const { return (path / n).string(); }
};

}  // namespace demcal::test
