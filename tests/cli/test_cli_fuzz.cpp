// Invalid mutations of the examples, fed to `demcal run`: exit 2, never a crash,
// and no database or output written.
#include "cli_util.hpp"

#include "jobs/job_error.hpp"
#include "jobs/job_spec.hpp"

#include <random>

using namespace demcal::test;

TEST(CliFuzz, InvalidMutationsExitTwoAndWriteNothing) {
  TempDir d;
  const std::string src = slurp(std::string(DEMCAL_EXAMPLES_DIR) + "/quickstart.json");
  std::mt19937 rng(99);
  int tried = 0;
  for (int i = 0; i < 2000 && tried < 40; ++i) {
    std::string t = src;
    const std::size_t pos = std::uniform_int_distribution<std::size_t>(0, t.size() - 1)(rng);
    if (rng() % 2) t.erase(pos, 1 + rng() % 4);
    else t.insert(pos, 1, "-0[{\",x9e"[rng() % 9]);
    try {
      demcal::jobs::parse_job(t, "m.json");
      continue;  // valid: running it would cost time; the in-process fuzz covers it
    } catch (const demcal::jobs::JobError&) {
    }
    ++tried;
    write(d.file("m.json"), t);
    const Result r = run_demcal({"run", "m.json", "--db", "fuzz.db"}, d.path.string());
    ASSERT_EQ(r.rc, 2) << t << "\n" << r.err;
    ASSERT_FALSE(r.err.empty());
    ASSERT_FALSE(fs::exists(d.file("fuzz.db"))) << t;
    ASSERT_FALSE(fs::exists(d.file("demcal-out"))) << t;
  }
  EXPECT_EQ(tried, 40);
}
