#include "jobs/grid.hpp"
#include "jobs/job_error.hpp"
#include "jobs/job_spec.hpp"
#include "jobs/material_params.hpp"
#include "jobs/physics_version.hpp"
#include "jobs/task_key.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <set>

using demcal::jobs::Job;
using demcal::jobs::parse_job;
using nlohmann::json;

namespace {
json base() {
  return json::parse(R"({
    "name": "g", "scene": "collision",
    "material": {"kn": 3e7, "diameter": {"min": 0.001, "max": 0.002}},
    "collision": {"particles": 20, "steps": 100}
  })");
}
Job parse(const json& j) { return parse_job(j.dump(), "test.json"); }
}  // namespace

TEST(Grid, SingleTaskWithoutLists) {
  const Job job = parse(base());
  ASSERT_EQ(job.tasks.size(), 1u);
  EXPECT_TRUE(job.axes.empty());
  const json& p = job.tasks[0].params;
  EXPECT_EQ(p["particles"], 20);
  EXPECT_EQ(p["seed"], 1);
  EXPECT_DOUBLE_EQ(p["dt_factor"].get<double>(), 0.3);  // resolved default: the timestep study's
  EXPECT_DOUBLE_EQ(p["energy_guard"].get<double>(), 0.02);
  EXPECT_EQ(p["sample_every"], 1);                      // steps / 200, at least 1
  EXPECT_FALSE(p.contains("dt"));
}

TEST(Grid, CartesianProductTimesReplicas) {
  json j = base();
  j["grid"] = {{"theta_deg", {10, 20, 30}}, {"eta", {0.0, 0.1}}};
  j["collision"]["particles"] = {20, 30};
  j["replicas"] = 2;
  j["seed"] = 7;
  const Job job = parse(j);
  EXPECT_EQ(job.tasks.size(), 3u * 2u * 2u * 2u);
  // Replicas are innermost, with distinct seeds.
  EXPECT_EQ(job.tasks[0].params["seed"], 7);
  EXPECT_EQ(job.tasks[1].params["seed"], 8);
  EXPECT_EQ(job.tasks[0].params.dump(), [&] { json p = job.tasks[1].params; p["seed"] = 7; return p.dump(); }());
  std::set<std::string> keys, combos;
  for (const auto& t : job.tasks) {
    keys.insert(t.key);
    combos.insert(t.params["theta_deg"].dump() + t.params["eta"].dump() + t.params["particles"].dump() +
                  t.params["seed"].dump());
  }
  EXPECT_EQ(keys.size(), job.tasks.size());
  EXPECT_EQ(combos.size(), job.tasks.size());
  for (std::size_t i = 0; i < job.tasks.size(); ++i) EXPECT_EQ(job.tasks[i].index, i);
  EXPECT_EQ(demcal::jobs::count_tasks(j.dump(), "test.json"), job.tasks.size());  // what status counts, unexpanded
}

// The product saturates instead of wrapping: eight axes of 256 values make exactly
// 2^64 tasks, which wrapped to 0, passed the task limit, and had the expansion fill
// memory until the process was killed.
TEST(Grid, AProductOfTwoToTheSixtyFourIsRefusedNotWrapped) {
  demcal::jobs::ParamSet set;
  for (int a = 0; a < 8; ++a) set.axes.push_back({"p" + std::to_string(a), "grid", std::vector<json>(256, json(1.0))});
  ASSERT_EQ(demcal::jobs::grid_size(set, 1), std::uint64_t(1) << 62);  // else the parse below fills memory
  set.axes.resize(7);
  EXPECT_EQ(demcal::jobs::grid_size(set, 1), std::uint64_t(1) << 56);
  EXPECT_EQ(demcal::jobs::grid_size(set, 256), std::uint64_t(1) << 62);

  json j = base();
  j["scene"] = "triaxial";
  j.erase("collision");
  j["triaxial"] = {{"packing", "dense"}};
  json grid = json::object();
  for (const char* name : {"theta_deg", "eta", "b", "kn", "ks", "confining_kpa", "strain_rate", "axial_strain"})
    grid[name] = json::array();
  for (int i = 0; i < 256; ++i) {  // all in range: the size alone is wrong
    grid["theta_deg"].push_back(10 + 0.1 * i);
    grid["eta"].push_back(0.001 * i);
    grid["b"].push_back(0.5 + 0.001 * i);
    grid["kn"].push_back(1e7 + 1e5 * i);
    grid["ks"].push_back(1e7 + 1e4 * i);
    grid["confining_kpa"].push_back(50 + i);
    grid["strain_rate"].push_back(1e-4 + 1e-6 * i);
    grid["axial_strain"].push_back(0.2 + 0.0003 * i);
  }
  j["grid"] = grid;
  try {
    parse(j);
    FAIL() << "a grid of 2^64 tasks was accepted";
  } catch (const demcal::jobs::JobError& e) {
    EXPECT_NE(std::string(e.what()).find("expands to at least 4611686018427387904 tasks, more than the limit"),
              std::string::npos) << e.what();
  }
  EXPECT_EQ(demcal::jobs::count_tasks(j.dump(), "test.json"), std::uint64_t(1) << 62);
}

TEST(Grid, GridOverridesBaseScalarAndNormalisesNumbers) {
  json j = base();
  j["material"]["theta_deg"] = 5;
  j["grid"] = {{"theta_deg", {30}}};
  j["collision"]["keep_friction"] = true;  // else theta is unused, and a second note says so
  const Job job = parse(j);
  ASSERT_EQ(job.tasks.size(), 1u);
  EXPECT_TRUE(job.tasks[0].params["theta_deg"].is_number_float());
  EXPECT_DOUBLE_EQ(job.tasks[0].params["theta_deg"].get<double>(), 30.0);
  // Legal, but the section's value is not used: the job says so.
  ASSERT_EQ(job.notes.size(), 1u);
  EXPECT_EQ(job.notes[0], "grid.theta_deg replaces material.theta_deg = 5.0");
  EXPECT_TRUE(parse(base()).notes.empty());
  // 30 and 30.0 are the same work: the same key.
  json k = base();
  k["material"]["theta_deg"] = 30.0;
  k["collision"]["keep_friction"] = true;
  EXPECT_EQ(parse(k).tasks[0].key, job.tasks[0].key);
}

TEST(Grid, AFrictionAngleThatLooksLikeRadiansIsNoted) {
  json j = base();
  j["collision"]["keep_friction"] = true;
  j["material"]["theta_deg"] = 0.5236;
  Job job = parse(j);
  ASSERT_EQ(job.notes.size(), 1u);
  EXPECT_EQ(job.notes[0], "material.theta_deg: the value 0.524 is at most pi/2, and theta is in degrees (a near "
                          "frictionless material); if it is radians, 0.524 rad is 30 degrees");
  EXPECT_DOUBLE_EQ(job.tasks[0].params["theta_deg"].get<double>(), 0.5236) << "legal: the value is used as given";
  j["material"].erase("theta_deg");
  j["grid"] = {{"theta_deg", {0.0, 0.35, 0.7}}};
  job = parse(j);
  ASSERT_EQ(job.notes.size(), 1u);
  EXPECT_EQ(job.notes[0].rfind("grid.theta_deg: every value is at most 0.7,", 0), 0u) << job.notes[0];
  // One value in degrees, or frictionless grains (0), is not a slip.
  j["grid"] = {{"theta_deg", {0.5, 20.0}}};
  EXPECT_TRUE(parse(j).notes.empty());
  j["grid"] = {{"theta_deg", {0.0}}};
  EXPECT_TRUE(parse(j).notes.empty());
}

TEST(Grid, AStepPastTheCriticalOneIsNotedBeforeTheRun) {
  json j = base();
  j["grid"] = {{"dt_factor", {0.1, 5.0}}};
  const Job job = parse(j);
  ASSERT_EQ(job.tasks.size(), 2u) << "legal: a stability study charts where the method fails";
  ASSERT_EQ(job.notes.size(), 1u);
  EXPECT_NE(job.notes[0].find("#1 (dt_factor=5.0)"), std::string::npos) << job.notes[0];
  EXPECT_NE(job.notes[0].find("exceeds the critical step"), std::string::npos) << job.notes[0];
  EXPECT_NE(job.notes[0].find("normal mode"), std::string::npos) << job.notes[0];
  EXPECT_NE(job.notes[0].find("will refuse it"), std::string::npos) << job.notes[0];

  // A stability study that asks to run past the limit is told what happens instead.
  j["collision"]["allow_unstable_dt"] = true;
  const Job study = parse(j);
  ASSERT_EQ(study.notes.size(), 1u);
  EXPECT_EQ(study.notes[0].find("will refuse"), std::string::npos) << study.notes[0];
  EXPECT_NE(study.notes[0].find("allow_unstable_dt runs it anyway"), std::string::npos) << study.notes[0];
  // ... and runs without the energy guard, whose gain is what it measures, unless it asks.
  EXPECT_DOUBLE_EQ(study.tasks[0].params["energy_guard"].get<double>(), -1.0);
  j["collision"]["energy_guard"] = 0.5;
  EXPECT_DOUBLE_EQ(parse(j).tasks[0].params["energy_guard"].get<double>(), 0.5);
}

TEST(Grid, KeyDependsOnSceneParamsAndIsStable) {
  const Job a = parse(base());
  const Job b = parse(base());
  EXPECT_EQ(a.tasks[0].key, b.tasks[0].key);
  EXPECT_EQ(a.tasks[0].key.size(), 32u);
  json j = base();
  j["name"] = "other-name";  // the job's name is not part of the work
  EXPECT_EQ(parse(j).tasks[0].key, a.tasks[0].key);
  j["seed"] = 2;
  EXPECT_NE(parse(j).tasks[0].key, a.tasks[0].key);
  EXPECT_NE(demcal::jobs::task_key("other", a.tasks[0].params), a.tasks[0].key);
}

TEST(Grid, KeysDoNotChangeBetweenBuilds) {
  // Stored databases are matched by key: a key that changed with a build (hash,
  // JSON number formatting, field order) would rerun every finished task. These were
  // computed outside the code (FNV-1a, 64 bit, two bases, over
  // "collision\n{\"a\":1.0,\"b\":\"x\"}\nphysics=2" and the same for "triaxial" with
  // physics=3); each scene's physics version is in its text.
  ASSERT_EQ(demcal::jobs::physics_version("collision"), 2) << "a new physics version changes the scene's keys: update this test on purpose";
  ASSERT_EQ(demcal::jobs::physics_version("repose"), 2) << "a new physics version changes the scene's keys: update this test on purpose";
  ASSERT_EQ(demcal::jobs::physics_version("triaxial"), 3) << "a new physics version changes the scene's keys: update this test on purpose";
  EXPECT_EQ(demcal::jobs::task_key("collision", json{{"b", "x"}, {"a", 1.0}}), "50c066ebd614bccdec7efb5d7d0f281a");
  EXPECT_EQ(demcal::jobs::task_key("triaxial", json{{"b", "x"}, {"a", 1.0}}), "28b49815f93f55aa5cb541c3054dd287");
  // And the defaults a job leaves out resolve as they did (the stored seed-study and
  // quickstart results are found under these keys).
  const auto first_key = [](const char* example) {
    return demcal::jobs::load_job_file(std::string(DEMCAL_EXAMPLES_DIR) + "/" + example).tasks.at(0).key;
  };
  EXPECT_EQ(first_key("quickstart.json"), "e128670c626396fb4bc1df738d8f9974");
  EXPECT_EQ(first_key("seed-study/table-2-2.json"), "9e254c978946e43bbbdd6591ef9c0d34");
  EXPECT_EQ(first_key("seed-study/repose.json"), "14c01a1b375fbf8944c48d90ccf66908");
  // Changed on purpose 2026-11-28: collision tasks resolve energy_guard (0.02, off where
  // allow_unstable_dt); a collision task is seconds to rerun.
  EXPECT_EQ(first_key("collision.json"), "8eda0e74d1e7ca7f5a7a2d7a0320a4bc");
}

TEST(Grid, FidelitySelectsDefaultSteps) {
  json j = base();
  j["collision"].erase("steps");
  j["fidelity"] = "quick";
  const auto quick = parse(j).tasks[0].params["steps"].get<long>();
  j["fidelity"] = "reference";
  const auto ref = parse(j).tasks[0].params["steps"].get<long>();
  EXPECT_LT(quick, ref);
  EXPECT_EQ(parse(j).fidelity, "reference");
}

TEST(Grid, DegreesBecomeRadiansOnlyInside) {
  json j = base();
  j["material"]["theta_deg"] = 30;
  const Job job = parse(j);
  EXPECT_DOUBLE_EQ(job.tasks[0].params["theta_deg"].get<double>(), 30.0);
  // ... and the engine gets radians: tan(30 deg) in the Coulomb cap.
  const demcal::engine::Material m = demcal::jobs::material_from(job.tasks[0].params);
  EXPECT_NEAR(m.friction_angle, M_PI / 6.0, 1e-15);
  EXPECT_NEAR(demcal::engine::contact_params(m).tan_theta, 1.0 / std::sqrt(3.0), 1e-15);
}

TEST(Grid, EveryExampleValidates) {
  int files = 0;
  for (const auto& entry : std::filesystem::recursive_directory_iterator(DEMCAL_EXAMPLES_DIR)) {
    if (entry.path().extension() != ".json") continue;
    ++files;
    const Job job = demcal::jobs::load_job_file(entry.path().string());
    EXPECT_GT(job.tasks.size(), 0u) << entry.path();
    EXPECT_EQ(demcal::jobs::count_tasks(job.spec.dump(), "x"), job.tasks.size()) << entry.path();
  }
  EXPECT_GE(files, 10);
  // The quickstart is a calibration: a (theta, eta) grid that map and fit can use.
  const Job quick = demcal::jobs::load_job_file(std::string(DEMCAL_EXAMPLES_DIR) + "/quickstart.json");
  EXPECT_EQ(quick.scene, "triaxial");
  EXPECT_EQ(quick.tasks.size(), 9u);
  std::set<double> thetas, etas;
  for (const auto& t : quick.tasks) {
    thetas.insert(t.params["theta_deg"].get<double>());
    etas.insert(t.params["eta"].get<double>());
  }
  EXPECT_EQ(thetas.size(), 3u);
  EXPECT_EQ(etas.size(), 3u);
}
