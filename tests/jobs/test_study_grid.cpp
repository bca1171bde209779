// What the timestep study needs from job files (issue 9): scene parameters that are
// not material parameters (dt_factor, keep_friction) as grid axes, and a collision
// run given by simulated time instead of steps.
#include "jobs/job_error.hpp"
#include "jobs/job_spec.hpp"

#include "engine/scenes/collision.hpp"

#include <gtest/gtest.h>

#include <cmath>

using demcal::jobs::Job;
using demcal::jobs::JobError;
using demcal::jobs::parse_job;
using nlohmann::json;

namespace {
json study_like() {
  return json::parse(R"({
    "name": "ts", "scene": "collision",
    "material": {"theta_deg": 30, "eta": 0.1},
    "collision": {"particles": 20, "duration": 1e-5, "allow_unstable_dt": true},
    "grid": {"keep_friction": [false, true], "dt_factor": [0.1, 0.5, 1.6]}
  })");
}
}  // namespace

TEST(StudyGrid, SceneParametersAreGridAxes) {
  const Job job = parse_job(study_like().dump(), "t.json");
  ASSERT_EQ(job.tasks.size(), 6u);
  // Grid keys expand in name order, the last varying fastest.
  EXPECT_EQ(job.axes, (std::vector<std::string>{"dt_factor", "keep_friction"}));
  EXPECT_EQ(job.tasks[0].params["keep_friction"], false);
  EXPECT_EQ(job.tasks[1].params["keep_friction"], true);
  EXPECT_DOUBLE_EQ(job.tasks[5].params["dt_factor"].get<double>(), 1.6);
  EXPECT_NE(job.tasks[0].key, job.tasks[1].key);
  // The duration replaces steps: no step count is invented.
  EXPECT_FALSE(job.tasks[0].params.contains("steps"));
}

TEST(StudyGrid, DurationAndStepsAreExclusive) {
  json j = study_like();
  j["collision"]["steps"] = 100;
  try {
    parse_job(j.dump(), "t.json");
    FAIL();
  } catch (const JobError& e) {
    EXPECT_EQ(e.path(), "collision.steps");
  }
  j = study_like();
  j["collision"]["duration"] = -1;
  EXPECT_THROW(parse_job(j.dump(), "t.json"), JobError);
}

TEST(StudyGrid, DurationGivesTheSameSimulatedTimeAtEveryStep) {
  demcal::engine::CollisionConfig c;
  c.particles = 30;
  c.solid_fraction = 0.2;
  c.duration = 2e-5;
  for (double k : {0.1, 0.4}) {
    c.dt_factor = k;
    const auto r = demcal::engine::run_collision(c);
    ASSERT_TRUE(r.outcome.ok()) << r.outcome.message;
    EXPECT_NEAR(r.simulated_seconds, 2e-5, r.dt);
    EXPECT_LE(r.energy.rows.size(), 202u);
    EXPECT_GT(r.energy.rows.size(), 100u);
  }
}

