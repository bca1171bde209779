#pragma once
// A scratch folder per test (process id and test name), removed afterwards.
#include <gtest/gtest.h>

#include <filesystem>
#include <string>
#include <unistd.h>

namespace demcal::test {

struct TempDir {
  std::filesystem::path path;
  TempDir() {
    path = std::filesystem::temp_directory_path() /
           ("demcal-db-test-" + std::to_string(getpid()) + "-" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::remove_all(path);
    std::filesystem::create_directories(path);
  }
  ~TempDir() { std::filesystem::remove_all(path); }
  std::string file(const std::string& n) const { return (path / n).string(); }
};

}  // namespace demcal::test
