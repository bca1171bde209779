// Scratch folders for gnuplot data and MPI results: fresh, private, removed.
#include "../temp_dir.hpp"
#include "jobs/private_temp_dir.hpp"

#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>
#include <sys/stat.h>

namespace demcal::jobs {
namespace {

TEST(PrivateTempDir, IsFreshPrivateAndRemovedWithItsFiles) {
  demcal::test::TempDir d;
  ::setenv("TMPDIR", d.path.c_str(), 1);
  std::filesystem::path first;
  {
    const PrivateTempDir a("demcal-plot"), b("demcal-plot");
    first = a.path();
    EXPECT_NE(a.path(), b.path());  // not a name another user could make in advance
    EXPECT_EQ(a.path().parent_path(), d.path);
    struct stat st {};
    ASSERT_EQ(::stat(a.path().c_str(), &st), 0);
    EXPECT_EQ(st.st_mode & 0777, 0700u);
    std::ofstream(a.file("data.txt")) << "1 2\n";
    EXPECT_TRUE(std::filesystem::exists(a.file("data.txt")));
  }
  EXPECT_FALSE(std::filesystem::exists(first));
  EXPECT_TRUE(std::filesystem::is_empty(d.path));
  ::unsetenv("TMPDIR");
}

}  // namespace
}  // namespace demcal::jobs
