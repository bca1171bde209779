// The timestep study's reading of its replicas (issue 9).
#include "calibrate/study.hpp"

#include <gtest/gtest.h>

#include <cmath>

// A factor's point over its replicas: the worst replica judges it (largest |drift|
// without friction, largest gain with it), mean and sd beside it, and one failed
// replica fails the point.
TEST(TimestepStudy, APointIsItsWorstReplicaAndFailsWithAnyReplica) {
  using demcal::jobs::ResultRow;
  auto row = [](const std::string& status, double drift) {
    ResultRow r;
    r.task.status = status;
    r.task.error = status == "done" ? "" : "unstable in stage collision: overlap";
    if (status == "done")
      r.metrics = {{"drift_per_simulated_s", drift}, {"dt", 6.45e-8}, {"max_relative_error", 1e-4 * std::abs(drift)},
                   {"wall_s_per_simulated_s", 300.0}};
    return r;
  };
  const std::vector<ResultRow> reps = {row("done", 0.05), row("done", -0.09), row("done", 0.02), row("done", -0.02)};
  const auto p = demcal::calibrate::timestep_point(false, 0.3, reps);
  ASSERT_TRUE(p.ok);
  EXPECT_EQ(p.replicas, 4);
  EXPECT_DOUBLE_EQ(p.drift, -0.09);  // the largest |drift|, its sign kept
  EXPECT_NEAR(p.drift_mean, -0.01, 1e-12);
  EXPECT_NEAR(p.drift_sd, std::sqrt((0.06 * 0.06 + 0.08 * 0.08 + 0.03 * 0.03 + 0.01 * 0.01) / 3.0), 1e-12);
  EXPECT_NEAR(p.max_relative_error, 9e-6, 1e-18);
  EXPECT_NEAR(p.cost, 300.0, 1e-9);
  // With friction the drift is dissipation: the worst replica is the one that loses least.
  const auto f = demcal::calibrate::timestep_point(true, 0.3, {row("done", -130.0), row("done", -140.0), row("done", -125.0)});
  EXPECT_DOUBLE_EQ(f.drift, -125.0);
  const auto g = demcal::calibrate::timestep_point(true, 1.4, {row("done", -70.0), row("done", 2.5)});
  EXPECT_DOUBLE_EQ(g.drift, 2.5);  // a gain
  const auto failed = demcal::calibrate::timestep_point(false, 2.0, {row("done", 0.01), row("failed", 0.0)});
  EXPECT_FALSE(failed.ok);
  EXPECT_NE(failed.error.find("unstable"), std::string::npos);
  EXPECT_FALSE(demcal::calibrate::timestep_point(false, 2.0, {}).ok);
}
