// The work forecast at a measured speed: done tasks' CPU time against the yardstick,
// and what is left of a job in a database.
#include "../temp_dir.hpp"
#include "db/merge.hpp"
#include "db/store.hpp"
#include "jobs/liveness.hpp"
#include "jobs/job_spec.hpp"
#include "jobs/progress.hpp"
#include "jobs/work_forecast.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <set>
#include <sstream>
#include <string>
#include <vector>

using namespace demcal;

namespace {

// Four quick triaxial tasks, two sample sizes (their yardsticks differ).
jobs::Job small_triaxial_job() {
  return jobs::parse_job(R"({"name": "wf", "scene": "triaxial", "fidelity": "quick",
                             "grid": {"particles": [300, 600], "eta": [0.0, 0.1]}})",
                         "wf.json");
}

double yardstick(const jobs::SceneDef& scene, const nlohmann::json& params) {
  return jobs::forecast_work(scene, {params}).core_seconds;
}

}  // namespace

TEST(WorkForecast, MeasuredSpeedIsTheMedianOfCpuTimeOverTheYardstick) {
  const jobs::Job job = small_triaxial_job();
  const jobs::SceneDef& scene = *jobs::find_scene("triaxial");
  ASSERT_EQ(job.tasks.size(), 4u);
  // Tasks 0 and 2 have 300 grains, 1 and 3 have 600: twice the work. Three done tasks
  // ran 1.5x, 2x and 10x (a busy machine) their yardstick.
  ASSERT_EQ(job.tasks[0].params["particles"], 300);
  ASSERT_EQ(job.tasks[1].params["particles"], 600);
  std::vector<jobs::DoneTask> done;
  const double ratios[] = {1.5, 2.0, 10.0};
  for (int k = 0; k < 3; ++k) {
    const double y = yardstick(scene, job.tasks[k].params);
    done.push_back({job.tasks[k].params, ratios[k] * y, 2 * ratios[k] * y, 1});  // wall: twice the CPU time
  }
  done.push_back({nlohmann::json{{"particles", "many"}}, 5.0, 5.0, 1});  // unreadable: passed over
  done.push_back({job.tasks[3].params, 0.0, 1.0, 1});                    // no time: passed over
  const jobs::MeasuredSpeed m = jobs::measure_speed(scene, done);
  EXPECT_EQ(m.tasks, 3);
  EXPECT_NEAR(m.factor, 2.0, 1e-12);
  EXPECT_NEAR(m.wall_factor, 4.0, 1e-12);
  EXPECT_EQ(m.threads, 1);
  // Weighted by work: a 600-grain task at 3x outweighs a 300-grain one at 1x.
  const double w300 = yardstick(scene, job.tasks[0].params), w600 = yardstick(scene, job.tasks[1].params);
  ASSERT_GT(w600, 1.9 * w300);
  EXPECT_NEAR(jobs::measure_speed(scene, {{job.tasks[0].params, w300, NAN, 0}, {job.tasks[1].params, 3 * w600, NAN, 0}})
                  .factor,
              3.0, 1e-12);

  // A task on two threads spent CPU time waiting for the other (6.8x in a user's
  // walk-through on a busy machine): a one-thread forecast leaves it out while
  // one-thread tasks are there, and says so when only it is.
  std::vector<jobs::DoneTask> mixed = {{job.tasks[0].params, 1.5 * w300, 1.5 * w300, 1},
                                       {job.tasks[1].params, 6.8 * w600, 3.4 * w600, 2}};
  EXPECT_NEAR(jobs::measure_speed(scene, mixed).factor, 1.5, 1e-12);
  EXPECT_NEAR(jobs::measure_speed(scene, mixed, 2).factor, 6.8, 1e-12);
  const jobs::MeasuredSpeed only_two = jobs::measure_speed(scene, {mixed[1]});
  EXPECT_EQ(only_two.threads, 2);
  const std::string said_two = jobs::describe(jobs::forecast_work(scene, {job.tasks[0].params}, only_two));
  EXPECT_NE(said_two.find("done triaxial task(s) in this database, run with 2 thread(s) ("), std::string::npos) << said_two;
  // Tasks from before the thread count was stored are not "differing": nothing is said.
  const jobs::MeasuredSpeed unrecorded = jobs::measure_speed(scene, {{job.tasks[0].params, w300, w300, 0}});
  EXPECT_EQ(unrecorded.threads, 0);
  const std::string said_old = jobs::describe(jobs::forecast_work(scene, {job.tasks[0].params}, unrecorded));
  EXPECT_EQ(said_old.find("run with"), std::string::npos) << said_old;
  const jobs::MeasuredSpeed mixed_old = jobs::measure_speed(scene, {mixed[1], {job.tasks[0].params, w300, w300, 0}});
  EXPECT_EQ(mixed_old.threads, jobs::MeasuredSpeed::kMixedThreads);
  EXPECT_NE(jobs::describe(jobs::forecast_work(scene, {job.tasks[0].params}, mixed_old)).find("differing thread counts"),
            std::string::npos);
  // Rows at the thread count asked for that cannot be read do not hide the others.
  EXPECT_EQ(jobs::measure_speed(scene, {mixed[1], {nlohmann::json{{"particles", "many"}}, 1.0, 1.0, 1}}).tasks, 1);

  std::vector<nlohmann::json> params;
  for (const auto& t : job.tasks) params.push_back(t.params);
  const jobs::WorkForecast plain = jobs::forecast_work(scene, params);
  const jobs::WorkForecast measured = jobs::forecast_work(scene, params, m);
  EXPECT_NEAR(measured.core_seconds, 2.0 * plain.core_seconds, 1e-9 * plain.core_seconds);
  EXPECT_EQ(measured.grain_steps, plain.grain_steps);
  const std::string said = jobs::describe(measured);
  EXPECT_NE(said.find("at the speed of the last 3 done triaxial task(s) in this database"), std::string::npos) << said;
  EXPECT_NE(said.find("2.00x the yardstick"), std::string::npos) << said;
  // The measured CPU time holds the preparation: the yardstick's caveat goes.
  EXPECT_EQ(said.find("the preparation adds"), std::string::npos) << said;
  EXPECT_NE(jobs::describe(plain).find("the preparation adds"), std::string::npos);
  // No done task: the yardstick, unchanged.
  EXPECT_EQ(jobs::measure_speed(scene, {}).tasks, 0);
}

TEST(WorkForecast, CpuSecondsLeftTakeWhatRunningTasksUsedOff) {
  // Queued 10 + 20; running: 30 with 4 s of wall on 2 threads (8 used), 5 with 9 s
  // (overdue: nothing left, not a negative), 7 with a clock gone backwards (nothing used).
  EXPECT_DOUBLE_EQ(jobs::cpu_seconds_left({10, 20}, {{30, 4}, {5, 9}, {7, -3}}, 2), 10 + 20 + 22 + 0 + 7);
  EXPECT_DOUBLE_EQ(jobs::cpu_seconds_left({}, {{30, 4}}, 1), 26);
  EXPECT_DOUBLE_EQ(jobs::cpu_seconds_left({}, {}, 1), 0);
}

TEST(WorkForecast, TheLastTaskToFinishSetsTheMakespan) {
  // Two workers, one running task with 8 s left, one with 1 s: 8 s, not their mean.
  EXPECT_DOUBLE_EQ(jobs::makespan({}, {8, 1}, 2), 8);
  // Queued tasks go to the first worker free: 1 + 3 = 4, then 4 + 5 = 9 (the other is busy until 8).
  EXPECT_DOUBLE_EQ(jobs::makespan({3, 5}, {8, 1}, 2), 9);
  // An idle worker takes a queued task at once.
  EXPECT_DOUBLE_EQ(jobs::makespan({2, 2, 2}, {}, 3), 2);
  EXPECT_DOUBLE_EQ(jobs::makespan({2, 2, 2}, {}, 2), 4);
  EXPECT_DOUBLE_EQ(jobs::makespan({}, {}, 4), 0);
}

TEST(WorkForecast, TimeLeftCountsPendingTasksAndWhatRunningOnesHaveNotUsed) {
  test::TempDir d;
  const jobs::Job job = small_triaxial_job();
  const jobs::SceneDef& scene = *jobs::find_scene("triaxial");
  db::Store store(d.file("wf.db"));
  std::vector<db::NewTask> tasks;
  for (const auto& t : job.tasks) tasks.push_back({t.key, "triaxial", t.params.dump()});
  store.put_job(job.name, job.spec.dump(), tasks);
  const auto rows = store.tasks(job.name);
  ASSERT_EQ(rows.size(), 4u);

  // Nothing measured yet: the yardstick, all four pending.
  jobs::TimeLeft t = jobs::time_left(store, job.name, db::unix_now());
  ASSERT_TRUE(t.known);
  EXPECT_EQ(t.pending, 4);
  EXPECT_EQ(t.running, 0);
  EXPECT_EQ(t.forecast.speed.tasks, 0);
  double all = 0;
  for (const auto& r : job.tasks) all += yardstick(scene, r.params);
  EXPECT_NEAR(t.core_seconds, all, 1e-9 * all);

  // Task 0 done at 3x its yardstick; task 1 running, started now and judged 1 s later.
  ASSERT_TRUE(store.claim(rows[0].id, "w"));
  db::Outcome out;
  out.status = "done";
  out.wall_s = 1;
  out.metrics = {{"cpu_s", 3.0 * yardstick(scene, job.tasks[0].params)}};
  ASSERT_TRUE(store.finish(rows[0].id, "w", out));
  const std::string me = jobs::runner_token();  // a runner at work (a dead one's task is counted whole)
  ASSERT_TRUE(store.claim(rows[1].id, me));
  const double started = store.task(rows[1].id)->started_at;
  t = jobs::time_left(store, job.name, started + 1.0);
  ASSERT_TRUE(t.known);
  EXPECT_EQ(t.pending, 2);
  EXPECT_EQ(t.running, 1);
  EXPECT_EQ(t.forecast.speed.tasks, 1);
  EXPECT_NEAR(t.forecast.factor(), 3.0, 1e-9);
  const double expected = 3.0 * (yardstick(scene, job.tasks[1].params) + yardstick(scene, job.tasks[2].params) +
                                 yardstick(scene, job.tasks[3].params)) - 1.0;
  EXPECT_NEAR(t.core_seconds, expected, 1e-6 * expected) << "the running task's second since it started is used";
  const std::string said = jobs::describe(t);
  EXPECT_NE(said.find("3 task(s) to go: "), std::string::npos) << said;
  EXPECT_NE(said.find(" at the 1 running now; at the speed of the last 1 done triaxial task(s)"), std::string::npos)
      << said;

  // The pending ones done, the running one long past its forecast: said so, not "under a minute".
  for (std::size_t k = 2; k < rows.size(); ++k) {
    ASSERT_TRUE(store.claim(rows[k].id, "w"));
    ASSERT_TRUE(store.finish(rows[k].id, "w", out));
  }
  t = jobs::time_left(store, job.name, started + 1e6);
  ASSERT_TRUE(t.known);
  EXPECT_EQ(t.core_seconds, 0.0);
  EXPECT_EQ(jobs::describe(t).rfind("1 task(s) to go: the running one has taken longer than forecast; at", 0), 0u)
      << jobs::describe(t);
  // Its runner gone (a token of a process that is not there): not running, all of it still to do.
  const std::string host = me.substr(0, me.find(':'));
  store.release(rows[1].id, me, "");
  const std::string dead = host + ":" + std::to_string(getpid()) + ":1";
  ASSERT_TRUE(store.claim(rows[1].id, dead));
  t = jobs::time_left(store, job.name, started + 1e6);
  EXPECT_EQ(t.running, 0);
  EXPECT_EQ(t.pending, 1);
  EXPECT_GT(t.core_seconds, 0.0);

  // Everything done: nothing to say.
  ASSERT_TRUE(store.finish(rows[1].id, dead, out));
  EXPECT_FALSE(jobs::time_left(store, job.name, db::unix_now()).known);
}

TEST(WorkForecast, ReposeIsBoundedByItsTimeLimitsUntilDoneTasksSayWhatItCosts) {
  const jobs::Job job = jobs::parse_job(R"({"name": "rp", "scene": "repose", "fidelity": "quick",
                                            "grid": {"eta": [0.1]}, "repose": {"time_limit": [1.0, 3.0]}})",
                                        "rp.json");
  const jobs::SceneDef& scene = *jobs::find_scene("repose");
  ASSERT_EQ(job.tasks.size(), 2u);
  std::vector<nlohmann::json> params;
  for (const auto& t : job.tasks) params.push_back(t.params);
  const jobs::WorkForecast bound = jobs::forecast_work(scene, params);
  ASSERT_TRUE(bound.known);
  EXPECT_TRUE(bound.upper_bound());
  // Both settlings (1.5 s each at quick) and the collapse, each to its limit: 4 s of
  // simulated time against 6 s.
  EXPECT_NEAR(bound.hi / bound.lo, (6.0 + 3 * 0.005) / (4.0 + 3 * 0.005), 1e-3);  // and a sample interval a stage
  const std::string said = jobs::describe(bound, 2);
  EXPECT_NE(said.find("at most"), std::string::npos) << said;
  EXPECT_EQ(said.find("about"), std::string::npos) << said;
  EXPECT_NE(said.find("comes to rest sooner costs less"), std::string::npos) << said;

  // A done task that cost a quarter of its bound: the forecast is an estimate now.
  const double yard = jobs::forecast_work(scene, {params[0]}).core_seconds;
  const jobs::MeasuredSpeed m = jobs::measure_speed(scene, {{params[0], 0.25 * yard, 0.25 * yard, 1}});
  ASSERT_EQ(m.tasks, 1);
  const jobs::WorkForecast measured = jobs::forecast_work(scene, params, m);
  EXPECT_FALSE(measured.upper_bound());
  EXPECT_NEAR(measured.core_seconds, 0.25 * bound.core_seconds, 1e-9 * bound.core_seconds);
  const std::string now = jobs::describe(measured);
  EXPECT_EQ(now.find("at most"), std::string::npos) << now;
  EXPECT_EQ(now.find("sooner"), std::string::npos) << now;
}

TEST(Progress, ABoundIsDrawnAsOne) {
  std::ostringstream out;
  jobs::Progress bar(out, /*terminal=*/true);
  bar.update({4, 1, 0, 1}, jobs::Eta{90.0, true});
  EXPECT_NE(out.str().find("ETA <= 1:30"), std::string::npos) << out.str();
  bar.line("task 2 done", {4, 2, 0, 1});  // redrawn with the ETA it was last given
  EXPECT_NE(out.str().rfind("ETA <= 1:30"), out.str().find("ETA <= 1:30")) << out.str();
  std::ostringstream plain;
  jobs::Progress estimate(plain, true);
  estimate.update({4, 1, 0, 1}, jobs::Eta{90.0, false});
  EXPECT_NE(plain.str().find("ETA 1:30"), std::string::npos) << plain.str();
  std::ostringstream unknown;
  jobs::Progress none(unknown, true);
  none.update({4, 0, 0, 1}, jobs::Eta{-1, true});  // nothing known: no bound to speak of
  EXPECT_NE(unknown.str().find("ETA --:--"), std::string::npos) << unknown.str();
  std::ostringstream late;
  jobs::Progress overdue(late, true);
  overdue.update({4, 3, 0, 1}, jobs::Eta{-1, false, true});
  EXPECT_NE(late.str().find("ETA past forecast"), std::string::npos) << late.str();
  // An estimate from the first tasks done, with the bound it came from beside it.
  std::ostringstream both;
  jobs::Progress beside(both, true);
  beside.update({4, 1, 0, 1}, jobs::Eta{12.0, false, false, 100.0});
  EXPECT_NE(both.str().find("ETA 12.0 s (<= 1:40)"), std::string::npos) << both.str();
}

TEST(WorkForecast, AFailedRunKeepsWhatItCostAndNoMechanics) {
  // Several times the critical step, run on purpose (a stability study): the instability
  // detector stops it.
  const jobs::Job job = jobs::parse_job(R"({"name": "boom", "scene": "collision",
      "collision": {"particles": 200, "steps": 2000, "dt_factor": 8, "allow_unstable_dt": true}})",
                                        "boom.json");
  const jobs::SceneDef& scene = *jobs::find_scene("collision");
  const jobs::SceneOutput out = scene.run(job.tasks[0].params, jobs::RunContext{1, nullptr});
  ASSERT_FALSE(out.outcome.ok()) << "the run was expected to fail";
  std::set<std::string> names;
  for (const auto& [name, value] : out.metrics) {
    names.insert(name);
    EXPECT_TRUE(db::is_timing_metric(name)) << name << " of a failed run";
  }
  EXPECT_TRUE(names.count("cpu_s")) << "a failure's cost is kept";
  EXPECT_TRUE(names.count("wall_s"));
  EXPECT_TRUE(names.count("threads"));
}

TEST(WorkForecast, LongWorkReadsInDays) {
  jobs::WorkForecast w;
  w.known = true;
  w.of = "the run";
  w.lo = w.hi = w.grain_steps = 1e12;
  w.core_seconds = 175 * 3600.0;
  EXPECT_NE(jobs::describe(w).find("about 7.3 days of one core"), std::string::npos) << jobs::describe(w);
  w.core_seconds = 30 * 3600.0;
  EXPECT_NE(jobs::describe(w).find("about 30 hours of one core"), std::string::npos) << jobs::describe(w);
  EXPECT_EQ(jobs::describe(w).find("check the settings"), std::string::npos) << jobs::describe(w);
}

// An absurd but valid setting (a strain rate of 1e-300 /s) forecast a number of days
// with hundreds of digits and nothing else: years, an exponent past a million, and
// a word that a task that long is a setting to check.
TEST(WorkForecast, AnAbsurdForecastReadsInYearsAndSaysSo) {
  jobs::WorkForecast w;
  w.known = true;
  w.of = "the shear";
  w.lo = w.hi = w.grain_steps = 7.4e304;
  const double year = 365.25 * 86400.0;
  for (const auto& [seconds, text] : std::vector<std::pair<double, std::string>>{
           {5.3e300, "about 1.7e+293 years of one core"}, {12.4 * year, "about 12 years of one core"}}) {
    w.core_seconds = seconds;
    w.task_core_seconds = {seconds};
    const std::string d = jobs::describe(w);
    EXPECT_NE(d.find(text), std::string::npos) << d;
    EXPECT_NE(d.find("a task would run for about"), std::string::npos) << d;
    EXPECT_NE(d.find("check the settings that set its steps"), std::string::npos) << d;
    EXPECT_LT(d.size(), 600u) << d;
  }
}
