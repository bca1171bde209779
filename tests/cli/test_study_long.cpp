// demcal study repose-fidelity --quick (issue 9): two column collapses of ~250
// grains, tens of seconds on one core, hence ctest label "long".
#include "cli_util.hpp"

using namespace demcal::test;

TEST(CliStudyLong, ReposeFidelityQuickChartsRecommendsAndReuses) {
  TempDir d;
  const std::vector<std::string> args = {"study", "repose-fidelity", "--quick", "--knobs", "depth",
                                         "--workers", "2", "--db", "s.db", "--out", "r"};
  const Result r = run_demcal(args, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err << r.out;
  for (const char* f : {"repose-fidelity-depth_depth.png", "repose-fidelity-depth.csv", "repose-fidelity-depth_recommendation.txt",
                        "jobs/study-repose-fidelity-quick-depth.json"}) {
    const fs::path p = d.path / "r" / f;
    EXPECT_TRUE(fs::exists(p) && fs::file_size(p) > 0) << f;
  }
  EXPECT_NE(r.out.find("2 tasks in s.db (0 reused, 2 run now)"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("depth: "), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("recommended settings (repose-fidelity"), std::string::npos) << r.out;
  const Result q = run_demcal({"query", "--db", "s.db", "--job", "study-repose-fidelity-quick-depth", "--format", "csv"},
                              d.path.string());
  EXPECT_EQ(q.rc, 0) << q.err;
  EXPECT_NE(q.out.find("repose_deg"), std::string::npos) << q.out;
  const Result again = run_demcal(args, d.path.string());
  ASSERT_EQ(again.rc, 0) << again.err;
  EXPECT_NE(again.out.find("2 tasks in s.db (2 reused, 0 run now)"), std::string::npos) << again.out;
}
