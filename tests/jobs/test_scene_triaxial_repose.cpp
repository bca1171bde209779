// The triaxial and repose scenes in the jobs layer: their parameter tables, the
// example jobs, fidelity presets, rejection of bad input naming the field, and one
// quick task of each run through the runner into a temporary store.
#include "../temp_dir.hpp"
#include "db/merge.hpp"
#include "db/store.hpp"
#include "jobs/job_error.hpp"
#include "jobs/job_spec.hpp"
#include "jobs/runner.hpp"
#include "jobs/scene_registry.hpp"

#include "jobs/material_params.hpp"

#include <gtest/gtest.h>

#include <tuple>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <map>
#include <set>
#include <sstream>
#include <unistd.h>

using demcal::jobs::Job;
using demcal::jobs::JobError;
using demcal::jobs::parse_job;
using nlohmann::json;
namespace fs = std::filesystem;

namespace {

json triaxial_base() {
  return json::parse(R"({
    "name": "tri", "scene": "triaxial",
    "material": {"kn": 3e7, "ks": 2.7e7, "density": 2650, "b": 1.0, "theta_deg": 30, "eta": 0.1,
                 "diameter": {"min": 0.001, "max": 0.002}},
    "triaxial": {"particles": 400, "packing": "dense", "confining_kpa": 100, "strain_rate": 1e-4,
                 "axial_strain": 0.3, "density_scale": 1e9},
    "grid": {"theta_deg": [20, 30]},
    "replicas": 1, "seed": 1
  })");
}

json repose_base() {
  return json::parse(R"({
    "name": "rep", "scene": "repose",
    "material": {"kn": 3e7, "ks": 2.7e7, "density": 2650, "b": 1.0, "theta_deg": 30, "eta": 0.1,
                 "diameter": {"min": 0.001, "max": 0.002}},
    "repose": {"column_width": 0.05, "column_height": 0.05, "depth_diameters": 4},
    "grid": {"eta": [0.0, 0.1]},
    "replicas": 1, "seed": 1
  })");
}

Job parse(const json& j) { return parse_job(j.dump(), "test.json"); }

// Every note the job draws, one a line.
std::string notes_of(const json& j) {
  std::string all;
  for (const auto& n : parse(j).notes) all += n + "\n";
  return all;
}

std::string error_of(const json& j) {
  try {
    parse(j);
  } catch (const JobError& e) {
    return e.what();
  }
  return "";
}

Job example(const char* name) { return demcal::jobs::load_job_file(std::string(DEMCAL_EXAMPLES_DIR) + "/" + name); }

}  // namespace

// ---- parameters and validation -------------------------------------------------

// A loose sample has no frictionless stage: the scale changes its key and nothing else.
TEST(TriaxialReposeScenes, FrictionlessStepScaleOnALooseSampleIsNotedUnused) {
  const char* note = "triaxial.frictionless_dt_scale is not used: a loose sample has no frictionless stage";
  json j = triaxial_base();
  j["triaxial"]["frictionless_dt_scale"] = 1.0;
  EXPECT_EQ(notes_of(j).find(note), std::string::npos) << notes_of(j);  // dense: used
  j["triaxial"]["packing"] = "loose";
  EXPECT_NE(notes_of(j).find(note), std::string::npos) << notes_of(j);
  j["triaxial"].erase("frictionless_dt_scale");
  EXPECT_EQ(notes_of(j).find(note), std::string::npos) << notes_of(j);
}

// With scaled_density (the default) the sand's own density enters nothing: a job
// that sets it, or a grid over it, runs the same work under different keys. Noted;
// with density_scale it is used, and not noted.
TEST(TriaxialReposeScenes, ADensityThatScaledDensityOverridesIsNotedUnused) {
  const std::string note = "material.density (2600 kg/m^3) is not used: the grains' density is triaxial.scaled_density";
  json j = triaxial_base();  // density_scale 1e9: the density is used
  j["material"]["density"] = 2600;
  EXPECT_EQ(notes_of(j).find("material.density ("), std::string::npos) << notes_of(j);
  j["triaxial"].erase("density_scale");  // the default scaled_density
  EXPECT_NE(notes_of(j).find(note), std::string::npos) << notes_of(j);
  j["material"]["density"] = 2650;  // the default: nothing to say
  EXPECT_EQ(notes_of(j).find("material.density ("), std::string::npos) << notes_of(j);
  // A grid over it: the tasks are named by their index in the grid, marked so that
  // it does not read as a task id (ids count from 1, indices from 0).
  j["grid"] = {{"theta_deg", {20, 30}}, {"density", {2600, 2650}}};
  EXPECT_NE(notes_of(j).find("tasks #0, #1: " + note), std::string::npos) << notes_of(j);
}

TEST(TriaxialReposeScenes, ExamplesValidate) {
  const Job t22 = example("table-2-2.json");
  EXPECT_EQ(t22.scene, "triaxial");
  EXPECT_EQ(t22.tasks.size(), 6u);
  const json& p = t22.tasks[0].params;
  EXPECT_EQ(p["packing"], "dense");
  EXPECT_DOUBLE_EQ(p["confining_kpa"].get<double>(), 100.0);
  EXPECT_DOUBLE_EQ(p["eta"].get<double>(), 0.1);
  EXPECT_EQ(p["particles"].get<long>(), 2000);  // the standard preset
  EXPECT_DOUBLE_EQ(p["cv_from"].get<double>(), 0.2);
  EXPECT_DOUBLE_EQ(p["cv_to"].get<double>(), 0.3);
  EXPECT_TRUE(p.contains("dt_factor"));

  const Job t23 = example("table-2-3.json");
  EXPECT_EQ(t23.tasks.size(), 4u);
  EXPECT_EQ(t23.tasks[0].params["packing"], "dense");
  std::set<std::string> keys;
  for (const auto& t : t22.tasks) keys.insert(t.key);
  for (const auto& t : t23.tasks) keys.insert(t.key);
  EXPECT_EQ(keys.size(), 9u);  // the two tables share theta = 30, eta = 0.1

  // The seed study's job files validate. The tables run three packings a row: the
  // first is the dense grid's task, and the three at (30 deg, 0.1) are the replicas job's.
  std::set<std::string> grid, replicas;
  for (const auto& t : example("seed-study/dense-grid.json").tasks) grid.insert(t.key);
  EXPECT_EQ(grid.size(), 24u);
  for (const auto& t : example("seed-study/replicas.json").tasks) replicas.insert(t.key);
  EXPECT_EQ(replicas.size(), 3u);
  for (const char* f : {"seed-study/table-2-2.json", "seed-study/table-2-3.json"}) {
    const Job table = example(f);
    EXPECT_EQ(table.tasks.size() % 3, 0u) << f;
    for (const auto& t : table.tasks) {
      const bool first = t.params["seed"].get<int>() == 1;
      EXPECT_EQ(grid.count(t.key), first ? 1u : 0u) << f;
      const bool centre = t.params["theta_deg"].get<double>() == 30.0 && t.params["eta"].get<double>() == 0.1;
      EXPECT_EQ(replicas.count(t.key), centre ? 1u : 0u) << f;
    }
  }
  EXPECT_EQ(example("seed-study/dense-loose-envelope.json").tasks.size(), 4u);
  EXPECT_EQ(example("seed-study/repose.json").tasks.size(), 5u);
  const Job walled = example("seed-study/repose-walled.json");
  ASSERT_EQ(walled.tasks.size(), 5u);
  EXPECT_EQ(walled.tasks[0].params["side_walls"].get<std::string>(), "frictional");
  EXPECT_DOUBLE_EQ(walled.tasks[0].params["depth_diameters"].get<double>(), 8.0);
  // The damping diagnostics: eta x damping x two packings, and Table 2.2 damped.
  const Job damped = example("seed-study/damping-in-shear.json");
  ASSERT_EQ(damped.tasks.size(), 32u);
  std::set<double> dampings;
  for (const auto& t : damped.tasks) dampings.insert(t.params.at("shear_damping").get<double>());
  EXPECT_EQ(dampings, (std::set<double>{0.0, 0.1, 0.2, 0.3}));
  const Job damped_theta = example("seed-study/damping-in-shear-theta.json");
  ASSERT_EQ(damped_theta.tasks.size(), 12u);
  for (const auto& t : damped_theta.tasks) EXPECT_EQ(t.params.at("shear_damping").get<double>(), 0.2);

  const Job rep = example("repose.json");
  EXPECT_EQ(rep.scene, "repose");
  EXPECT_EQ(rep.tasks.size(), 48u);
  EXPECT_DOUBLE_EQ(rep.tasks[0].params["column_width"].get<double>(), 0.05);
  EXPECT_DOUBLE_EQ(rep.tasks[0].params["depth_diameters"].get<double>(), 4.0);
  // side_walls has no default in the task parameters: jobs written before it
  // existed keep their task keys (and their stored results).
  EXPECT_FALSE(rep.tasks[0].params.contains("side_walls"));
  // Nor have the rest-by-profile settings: the check only turns runs that would end
  // not_settled into results, so stored results keep their keys.
  EXPECT_FALSE(rep.tasks[0].params.contains("rest_profile_window"));
  EXPECT_FALSE(rep.tasks[0].params.contains("rest_profile_tol_deg"));
  // The grading likewise: uniform by number unless a job names another.
  EXPECT_FALSE(rep.tasks[0].params.contains("size_distribution"));

  const Job walls = example("repose-side-walls.json");
  ASSERT_EQ(walls.tasks.size(), 6u);
  for (const auto& t : walls.tasks) EXPECT_EQ(t.params["side_walls"].get<std::string>(), "frictional");
}

TEST(TriaxialReposeScenes, AGradingIsATaskParameterAndAGridAxis) {
  json j = triaxial_base();
  j["material"]["diameter"]["distribution"] = "log_uniform_mass";
  const Job one = parse(j);
  ASSERT_EQ(one.tasks.size(), 2u);  // theta 20 and 30
  EXPECT_EQ(one.tasks[0].params["size_distribution"], "log_uniform_mass");
  j = triaxial_base();
  j["grid"] = {{"size_distribution", {"uniform", "uniform_mass"}}};
  const Job two = parse(j);
  ASSERT_EQ(two.tasks.size(), 2u);
  EXPECT_NE(two.tasks[0].key, two.tasks[1].key);
  // Naming the default is leaving it out: the same key, no parameter.
  j = triaxial_base();
  j.erase("grid");
  EXPECT_EQ(two.tasks[0].key, parse(j).tasks[0].key);
  EXPECT_FALSE(two.tasks[0].params.contains("size_distribution"));
  // The quick repose slab keeps its depth in metres under a finer grading: in units
  // of the smaller mean diameter it would be thinner than the periodic images allow.
  json r = repose_base();
  r["repose"].erase("depth_diameters");
  r["fidelity"] = "quick";
  const double d_uniform = parse(r).tasks[0].params["depth_diameters"].get<double>() * 1.5e-3;
  for (const char* g : {"uniform_mass", "log_uniform_mass"}) {
    r["material"]["diameter"]["distribution"] = g;
    EXPECT_EQ(error_of(r), "") << g;
    const Job rep = parse(r);
    demcal::engine::SizeDistribution s = demcal::engine::SizeDistribution::uniform;
    ASSERT_TRUE(demcal::engine::parse_size_distribution(g, s));
    const demcal::engine::Grading grading{s, 1e-3, 2e-3};
    EXPECT_NEAR(rep.tasks[0].params["depth_diameters"].get<double>() * grading.mean(), d_uniform, 1e-12) << g;
  }
}

// A sand's sieve analysis: sizes in m, percent of the mass finer.
json sand_curve() {
  return {{"d", {0.0006, 0.001, 0.00118, 0.0014, 0.0017, 0.002, 0.00236}},
          {"percent_finer", {0, 10, 25, 55, 80, 95, 100}}};
}

TEST(TriaxialReposeScenes, AMeasuredGradingCurveRunsFromItsFirstSizeToItsLastOrIsCut) {
  json j = triaxial_base();
  j["material"]["diameter"] = {{"grading", sand_curve()}};
  const Job whole = parse(j);
  const json& p = whole.tasks[0].params;
  EXPECT_EQ(p["d_min"].get<double>(), 0.0006);
  EXPECT_EQ(p["d_max"].get<double>(), 0.00236);
  EXPECT_EQ(p["size_distribution"], "log_uniform_mass");  // a sieve chart's straight lines
  const demcal::engine::Material m = demcal::jobs::material_from(p);
  ASSERT_EQ(m.grading_curve.finer.size(), 7u);
  EXPECT_EQ(m.grading_curve.finer[2], 0.25);
  EXPECT_EQ(m.grading_curve.finer.back(), 1.0);
  EXPECT_NEAR(m.grading().finer_by_mass(0.0014), 0.55, 1e-15);

  // Cut to [1, 2] mm, the range the seed's simulations afford: renormalised.
  j["material"]["diameter"]["min"] = 0.001;
  j["material"]["diameter"]["max"] = 0.002;
  const Job cut = parse(j);
  EXPECT_EQ(cut.tasks[0].params["d_min"].get<double>(), 0.001);
  EXPECT_NEAR(demcal::jobs::material_from(cut.tasks[0].params).grading().finer_by_mass(0.0014), 45.0 / 85.0, 1e-15);
  EXPECT_NE(cut.tasks[0].key, whole.tasks[0].key);
  // Straight lines in d instead, when the job says so: another grading, another key.
  j["material"]["diameter"]["distribution"] = "uniform_mass";
  EXPECT_NE(parse(j).tasks[0].key, cut.tasks[0].key);

  // Two measured curves as a grid axis.
  j = triaxial_base();
  json finer = sand_curve();
  finer["percent_finer"] = {0, 30, 50, 70, 85, 95, 100};
  j["grid"] = {{"grading", {sand_curve(), finer}}};
  const Job two = parse(j);
  ASSERT_EQ(two.tasks.size(), 2u);
  EXPECT_NE(two.tasks[0].key, two.tasks[1].key);
  EXPECT_LT(demcal::jobs::material_from(two.tasks[1].params).grading().mean(),
            demcal::jobs::material_from(two.tasks[0].params).grading().mean());

  // Sieves listed at 0% below the finest grain, or at 100% above the coarsest, do not
  // widen the range: the smallest grain sets the time step.
  j = triaxial_base();
  j["material"]["diameter"] = {{"grading", {{"d", {0.000075, 0.00015, 0.0003, 0.0006, 0.001, 0.002, 0.004}},
                                            {"percent_finer", {0, 0, 0, 0, 50, 100, 100}}}}};
  const Job flat = parse(j);
  EXPECT_EQ(flat.tasks[0].params["d_min"].get<double>(), 0.0006);
  EXPECT_EQ(flat.tasks[0].params["d_max"].get<double>(), 0.002);

  // A job without a curve keeps the engine's range (and its keys: Grid.* and the examples).
  const Job plain = parse(triaxial_base());
  EXPECT_EQ(plain.tasks[0].params["d_min"].get<double>(), 0.001);
  EXPECT_EQ(plain.tasks[0].params["d_max"].get<double>(), 0.002);
  EXPECT_FALSE(plain.tasks[0].params.contains("grading"));
}

TEST(TriaxialReposeScenes, AGradingCurveThatIsNotOneSaysWhereAndWhy) {
  const auto with = [](const std::function<void(json&)>& edit) {
    json j = triaxial_base();
    j["material"]["diameter"] = {{"grading", sand_curve()}};
    edit(j);
    return error_of(j);
  };
  const auto starts = [](const std::string& msg, const std::string& field, const std::string& words) {
    return msg.rfind(field, 0) == 0 && msg.find(words) != std::string::npos;
  };
  EXPECT_PRED3(starts, with([](json& j) { j["material"]["diameter"]["grading"] = json::array({1, 2}); }),
               "material.diameter.grading", "expected {\"d\"");
  EXPECT_PRED3(starts, with([](json& j) { j["material"]["diameter"]["grading"].erase("percent_finer"); }),
               "material.diameter.grading.percent_finer", "missing");
  EXPECT_PRED3(starts, with([](json& j) { j["material"]["diameter"]["grading"]["passing"] = 1; }),
               "material.diameter.grading.passing", "unknown key");
  EXPECT_PRED3(starts, with([](json& j) { j["material"]["diameter"]["grading"]["d"][3] = "1.4 mm"; }),
               "material.diameter.grading.d[3]", "expected a number");
  EXPECT_PRED3(starts, with([](json& j) { j["material"]["diameter"]["grading"]["d"][3] = 1.4; }),
               "material.diameter.grading.d[3]", "(0, 1] m");
  EXPECT_PRED3(starts, with([](json& j) { j["material"]["diameter"]["grading"]["percent_finer"][2] = 0.25; }),
               "material.diameter.grading", "point 3 (d = 0.00118 m): the mass finer must not decrease");
  EXPECT_PRED3(starts, with([](json& j) { j["material"]["diameter"]["grading"]["percent_finer"][6] = 120; }),
               "material.diameter.grading.percent_finer[6]", "[0, 100] percent");
  EXPECT_PRED3(starts, with([](json& j) { j["material"]["diameter"]["grading"]["percent_finer"].erase(6); }),
               "material.diameter.grading", "one percentage per size");
  EXPECT_PRED3(starts, with([](json& j) { j["material"]["diameter"]["grading"]["d"][2] = 0.0009; }),
               "material.diameter.grading.d[2]", "the sizes must increase (smallest sieve first), got 0.0009 after 0.001");
  EXPECT_PRED3(starts, with([](json& j) { j["material"]["diameter"]["grading"]["percent_finer"][6] = 99; }),
               "material.diameter.grading", "100%");
  EXPECT_PRED3(starts, with([](json& j) { j["material"]["diameter"]["distribution"] = "uniform"; }),
               "material.diameter.distribution", "log_uniform_mass");
  EXPECT_PRED3(starts, with([](json& j) { j["material"]["diameter"]["min"] = 0.0005; }),
               "material.diameter.grading", "within the curve's sizes");
  EXPECT_PRED3(starts, with([](json& j) { j["material"]["diameter"]["grading"]["d"] = std::vector<double>(1001, 1e-3); }),
               "material.diameter.grading.d", "more than the 1000");
  EXPECT_PRED3(starts, with([](json& j) { j["material"]["diameter"]["grading"] = {{"d", json::array()}, {"percent_finer", json::array()}}; }),
               "material.diameter.grading.d", "at least two points");
  EXPECT_PRED3(starts, with([](json& j) { j["material"]["diameter"]["grading"]["percent_finer"] = {100}; j["material"]["diameter"]["grading"]["d"] = {0.001}; }),
               "material.diameter.grading.d", "at least two points");
  EXPECT_PRED3(starts, with([](json& j) { j["material"]["diameter"]["min"] = 0.0015; j["material"]["diameter"]["max"] = 0.0015; }),
               "material.diameter.grading", "min and max must differ");
  EXPECT_PRED3(starts, with([](json& j) { j["material"]["diameter"]["max"] = 0.0005; }), "material.diameter.max",
               "must exceed the curve's largest size with nothing finer, 0.0006");
  EXPECT_PRED3(starts, with([](json& j) { j["material"]["diameter"]["min"] = 0.0025; }), "material.diameter.min",
               "must be below the curve's smallest size with everything finer, 0.00236");
  // A curve the grid varies is blamed where its value was written.
  EXPECT_PRED3(starts, with([](json& j) {
                 json bad = sand_curve();
                 bad["percent_finer"][2] = 5;
                 j["material"]["diameter"].erase("grading");
                 j["grid"] = {{"grading", {sand_curve(), bad}}};
               }),
               "grid.grading[1]", "point 3 (d = 0.00118 m)");
  EXPECT_PRED3(starts, with([](json& j) { j["grid"] = {{"size_distribution", {"log_uniform_mass", "uniform"}}}; }),
               "grid.size_distribution[1]", "draws by number");
  EXPECT_PRED3(starts, with([](json& j) { j["grid"] = {{"grading", {sand_curve(), 3}}}; }), "grid.grading[1]",
               "expected {\"d\"");
}

TEST(TriaxialReposeScenes, SideWallsBetweenWallsMayBeThinnerThanThePeriodicSlab) {
  json j = repose_base();
  j["repose"]["depth_diameters"] = 2.0;  // 3 mm: periodic images of a 2 mm grain would interact
  EXPECT_NE(error_of(j).find("repose.depth_diameters"), std::string::npos);
  j["repose"]["side_walls"] = "smooth";
  EXPECT_EQ(error_of(j), "");
}

TEST(TriaxialReposeScenes, ConfiningPressureAndPackingAreGridAxes) {
  json j = triaxial_base();
  j["grid"] = {{"confining_kpa", {50, 100, 200}}, {"packing", {"dense", "loose"}}};
  const Job job = parse(j);
  ASSERT_EQ(job.tasks.size(), 6u);
  std::set<std::string> keys;
  std::set<std::pair<double, std::string>> seen;
  for (const auto& t : job.tasks) {
    keys.insert(t.key);
    seen.insert({t.params["confining_kpa"].get<double>(), t.params["packing"].get<std::string>()});
  }
  EXPECT_EQ(keys.size(), 6u);
  EXPECT_EQ(seen.size(), 6u);
  EXPECT_TRUE(seen.count({200.0, "loose"}));
  // A list in the section is an axis too.
  json k = triaxial_base();
  k["triaxial"]["packing"] = {"dense", "loose"};
  EXPECT_EQ(parse(k).tasks.size(), 4u);
}

TEST(TriaxialReposeScenes, FidelityFillsWhatTheJobOmits) {
  json j = triaxial_base();
  j["triaxial"].erase("particles");
  j["triaxial"].erase("strain_rate");
  std::map<std::string, json> by;
  for (const char* f : {"quick", "standard", "reference"}) {
    j["fidelity"] = f;
    by[f] = parse(j).tasks[0].params;
  }
  EXPECT_LT(by["quick"]["particles"].get<long>(), by["standard"]["particles"].get<long>());
  EXPECT_LT(by["standard"]["particles"].get<long>(), by["reference"]["particles"].get<long>());
  EXPECT_GT(by["quick"]["strain_rate"].get<double>(), by["standard"]["strain_rate"].get<double>());
  EXPECT_EQ(by["standard"]["particles"].get<long>(), 2000);
  // What the job gives wins over the preset.
  j["fidelity"] = "quick";
  j["triaxial"]["particles"] = 1000;
  EXPECT_EQ(parse(j).tasks[0].params["particles"].get<long>(), 1000);

  json r = repose_base();
  r["repose"] = json::object();
  r["fidelity"] = "quick";
  const json q = parse(r).tasks[0].params;
  r["fidelity"] = "reference";
  const json ref = parse(r).tasks[0].params;
  EXPECT_LT(q["column_width"].get<double>(), ref["column_width"].get<double>());
  EXPECT_LT(q["stiffness_scale"].get<double>(), ref["stiffness_scale"].get<double>());
  EXPECT_LT(q["time_limit"].get<double>(), ref["time_limit"].get<double>());
}

TEST(TriaxialReposeScenes, CriticalStateWindowFollowsTheAxialStrain) {
  json j = triaxial_base();
  j["triaxial"]["axial_strain"] = 0.15;
  const json p = parse(j).tasks[0].params;
  EXPECT_DOUBLE_EQ(p["cv_to"].get<double>(), 0.15);
  EXPECT_DOUBLE_EQ(p["cv_from"].get<double>(), 0.1);
}

namespace {
struct Bad {
  const char* name;
  bool repose;                        // mutate repose_base() instead of triaxial_base()
  std::function<void(json&)> mutate;
  const char* field;                  // must appear in the message
};

const std::vector<Bad>& bad_cases() {
  static const std::vector<Bad> v = {
      {"confining_negative", false, [](json& j) { j["triaxial"]["confining_kpa"] = -100; }, "triaxial.confining_kpa"},
      {"confining_zero_in_grid", false, [](json& j) { j["grid"]["confining_kpa"] = {100, 0}; }, "grid.confining_kpa[1]"},
      {"packing_unknown", false, [](json& j) { j["triaxial"]["packing"] = "medium"; }, "triaxial.packing"},
      {"packing_unknown_in_grid", false, [](json& j) { j["grid"]["packing"] = {"dense", "lose"}; }, "grid.packing[1]"},
      {"packing_number", false, [](json& j) { j["triaxial"]["packing"] = 1; }, "triaxial.packing"},
      {"eta_negative", false, [](json& j) { j["material"]["eta"] = -0.1; }, "material.eta"},
      {"eta_negative_in_grid", false, [](json& j) { j["grid"]["eta"] = {0.1, -0.2}; }, "grid.eta[1]"},
      {"theta_90", false, [](json& j) { j["grid"]["theta_deg"] = {30, 90}; }, "grid.theta_deg[1]"},
      {"dt_and_dt_factor", false, [](json& j) { j["triaxial"]["dt"] = 1e-3; j["triaxial"]["dt_factor"] = 0.2; }, "triaxial.dt"},
      {"density_scale_and_scaled_density", false, [](json& j) { j["triaxial"]["scaled_density"] = 2.65e12; }, "triaxial.density_scale"},
      {"particles_too_few", false, [](json& j) { j["triaxial"]["particles"] = 10; }, "triaxial.particles"},
      {"strain_rate_zero", false, [](json& j) { j["triaxial"]["strain_rate"] = 0; }, "triaxial.strain_rate"},
      {"axial_strain_too_large", false, [](json& j) { j["triaxial"]["axial_strain"] = 0.7; }, "triaxial.axial_strain"},
      {"cv_to_beyond_axial_strain", false, [](json& j) { j["triaxial"]["cv_to"] = 0.35; }, "triaxial.cv_to"},
      {"cv_from_above_cv_to", false, [](json& j) { j["triaxial"]["cv_from"] = 0.3; j["triaxial"]["cv_to"] = 0.25; }, "triaxial.cv_from"},
      {"sample_strain_beyond", false, [](json& j) { j["triaxial"]["axial_strain"] = 0.01; j["triaxial"]["sample_strain"] = 0.02; }, "triaxial.sample_strain"},
      {"aspect_ratio_too_large", false, [](json& j) { j["triaxial"]["aspect_ratio"] = 5; }, "triaxial.aspect_ratio"},
      {"servo_alpha_too_large", false, [](json& j) { j["triaxial"]["servo_alpha"] = 1.5; }, "triaxial.servo_alpha"},
      {"shear_damping_one", false, [](json& j) { j["triaxial"]["shear_damping"] = 1.0; }, "triaxial.shear_damping"},
      {"shear_damping_negative_in_grid", false, [](json& j) { j["grid"]["shear_damping"] = {0.0, -0.1}; }, "grid.shear_damping[1]"},
      {"prep_damping_one", false, [](json& j) { j["triaxial"]["prep_damping"] = 1.0; }, "triaxial.prep_damping"},
      {"frictionless_dt_scale_zero", false, [](json& j) { j["triaxial"]["frictionless_dt_scale"] = 0; }, "triaxial.frictionless_dt_scale"},
      {"frictionless_dt_scale_past_its_limit", false, [](json& j) { j["triaxial"]["frictionless_dt_scale"] = 5.0; }, "triaxial.frictionless_dt_scale"},
      {"triaxial_typo", false, [](json& j) { j["triaxial"]["confining_kPa"] = 100; }, "triaxial.confining_kPa"},
      {"repose_section_in_triaxial_job", false, [](json& j) { j["repose"] = json::object(); }, "repose"},
      {"repose_dt_and_dt_factor", true, [](json& j) { j["repose"]["dt"] = 1e-6; j["repose"]["dt_factor"] = 0.3; }, "repose.dt"},
      {"repose_particles_not_a_knob", true, [](json& j) { j["repose"]["particles"] = 3000; }, "repose.particles"},
      {"repose_eta_negative", true, [](json& j) { j["grid"]["eta"] = {-0.1}; }, "grid.eta[0]"},
      {"repose_slab_too_thin", true, [](json& j) { j["repose"]["depth_diameters"] = 1.5; }, "repose.depth_diameters"},
      {"size_distribution_unknown", false, [](json& j) { j["material"]["diameter"]["distribution"] = "lognormal"; }, "material.diameter.distribution"},
      {"repose_profile_window_negative", true, [](json& j) { j["repose"]["rest_profile_window"] = -1; }, "repose.rest_profile_window"},
      {"repose_profile_window_past_the_limit", true, [](json& j) { j["repose"]["time_limit"] = 1.5; j["repose"]["rest_profile_window"] = 5; }, "repose.rest_profile_window"},
      {"repose_profile_window_one_sample", true, [](json& j) { j["repose"]["rest_profile_window"] = 0.005; }, "repose.rest_profile_window"},
      {"repose_profile_tol_zero", true, [](json& j) { j["repose"]["rest_profile_tol_deg"] = 0; }, "repose.rest_profile_tol_deg"},
      {"repose_side_walls_unknown", true, [](json& j) { j["repose"]["side_walls"] = "rough"; }, "repose.side_walls"},
      {"repose_side_walls_too_close", true, [](json& j) { j["repose"]["side_walls"] = "frictional"; j["repose"]["depth_diameters"] = 1.0; }, "repose.depth_diameters"},
      {"repose_column_too_narrow", true, [](json& j) { j["repose"]["column_width"] = 0.003; }, "repose.column_width"},
      {"repose_column_too_short", true, [](json& j) { j["repose"]["column_height"] = 0.0001; }, "repose.column_height"},
      {"repose_time_limit_below_default_min_collapse", true, [](json& j) { j["repose"]["time_limit"] = 0.001; }, "repose.time_limit"},
      {"repose_stiffness_scale_above_one", true, [](json& j) { j["repose"]["stiffness_scale"] = 2; }, "repose.stiffness_scale"},
      {"repose_fit_window_inverted", true, [](json& j) { j["repose"]["fit_lo"] = 0.8; j["repose"]["fit_hi"] = 0.5; }, "repose.fit_hi"},
      // fit_hi left at its default: the fit_lo the job wrote is named, in the grid too.
      {"repose_fit_lo_above_default_hi", true, [](json& j) { j["repose"]["fit_lo"] = 0.9; }, "repose.fit_lo"},
      {"repose_fit_lo_axis_above_default_hi", true, [](json& j) { j["grid"]["fit_lo"] = {0.2, 0.9}; }, "grid.fit_lo[1]"},
      {"repose_time_limit_negative", true, [](json& j) { j["repose"]["time_limit"] = -1; }, "repose.time_limit"},
      {"repose_min_collapse_beyond_limit", true, [](json& j) { j["repose"]["time_limit"] = 0.1; j["repose"]["min_collapse_time"] = 0.2; }, "repose.min_collapse_time"},
      {"repose_rest_trim_large", true, [](json& j) { j["repose"]["rest_trim"] = 0.5; }, "repose.rest_trim"},
      {"repose_domain_too_short", true, [](json& j) { j["repose"]["domain_length"] = 0.04; }, "repose.domain_length"},
  };
  return v;
}
}  // namespace

TEST(TriaxialReposeScenes, ANotQuasiStaticShearIsNotedBeforeTheRun) {
  // I = rate * d_mean * sqrt(rho / p0): 1e-4 /s * 1.5 mm * sqrt(2.65e12 / 1e5) = 7.7e-4,
  // below the limit 1e-3; 5e-4 /s gives 3.9e-3, which the run would warn about.
  auto inertial_notes = [](const Job& job) {
    std::vector<std::string> v;
    for (const auto& n : job.notes)
      if (n.find("inertial number") != std::string::npos) v.push_back(n);
    return v;
  };
  json j = triaxial_base();
  EXPECT_TRUE(inertial_notes(parse(j)).empty());
  j["triaxial"]["strain_rate"] = 5e-4;
  auto notes = inertial_notes(parse(j));
  ASSERT_EQ(notes.size(), 1u);
  EXPECT_EQ(notes[0].rfind("all 2 tasks: inertial number 0.0039 at p0", 0), 0u) << notes[0];
  EXPECT_NE(notes[0].find("the run will warn not quasi-static"), std::string::npos) << notes[0];
  j["grid"] = {{"strain_rate", {1e-4, 5e-4}}};
  notes = inertial_notes(parse(j));
  ASSERT_EQ(notes.size(), 1u);
  EXPECT_EQ(notes[0].rfind("task #1: inertial number", 0), 0u) << notes[0];
}

// What the inputs already say will go wrong in preparation, said before the run: a
// load the stiffness cannot carry, walls too slow to pack the grains within the
// budget, a step close to the critical one.
TEST(TriaxialReposeScenes, APreparationTheSettingsDoomAreNotedBeforeTheRun) {
  const json base = triaxial_base();
  const std::string plain = notes_of(base);
  for (const char* what :
       {"kn / (p d_min)", "the preparation's walls", "of the critical step of an isolated pair", "the shear is only",
        "close in fast enough"})
    EXPECT_EQ(plain.find(what), std::string::npos) << plain;
  json j = base;
  j["triaxial"]["confining_kpa"] = 10000;  // a dense preparation at 1 GPa: kn / (p d_min) = 30
  EXPECT_NE(notes_of(j).find("kn / (p d_min) is 30 at 1e+09 Pa, the preparation's highest mean stress"),
            std::string::npos)
      << notes_of(j);
  // Grains 2,700 times softer than the seed's at its preparation rate: the walls ram
  // them (the run blows up in isotropic_compression); the note names the rate that does not.
  j = base;
  j["material"]["kn"] = 1.1e4;
  j["material"]["ks"] = 9900;
  j["triaxial"]["prep_pressure_factor"] = 1;
  EXPECT_NE(notes_of(j).find("close in fast enough (triaxial.prep_strain_rate 0.02 /s) to press the largest grain 14% "
                            "of its radius into a wall"),
            std::string::npos)
      << notes_of(j);
  EXPECT_NE(notes_of(j).find("lower triaxial.confining_kpa or raise material.kn"), std::string::npos) << notes_of(j);
  EXPECT_EQ(notes_of(j).find("lower triaxial.prep_pressure_factor"), std::string::npos) << notes_of(j);
  j["triaxial"]["prep_strain_rate"] = 0.0013;
  EXPECT_EQ(notes_of(j).find("close in fast enough"), std::string::npos) << notes_of(j);
  j = base;
  j["material"]["diameter"] = {{"min", 1e-5}, {"max", 2e-5}};  // a 1000x finer step
  EXPECT_NE(notes_of(j).find("need about"), std::string::npos) << notes_of(j);
  EXPECT_NE(notes_of(j).find("more than triaxial.prep_step_budget (400000)"), std::string::npos) << notes_of(j);
  j = base;
  j["triaxial"]["strain_rate"] = 1.0;
  j["triaxial"]["axial_strain"] = 0.05;
  EXPECT_NE(notes_of(j).find("the shear is only "), std::string::npos) << notes_of(j);
  j = base;
  j["material"]["theta_deg"] = 0;
  j["grid"] = {{"eta", {0.0, 0.5}}};
  EXPECT_NE(notes_of(j).find("task #0: material.theta_deg is 0 (also its default when a job leaves it out): the grains are "
                            "frictionless, and the test measures a frictionless packing's angles, not a sand's\n"),
            std::string::npos)
      << notes_of(j);
  EXPECT_NE(notes_of(j).find("not a sand's; material.eta exerts no moment at theta_deg 0"), std::string::npos) << notes_of(j);
  EXPECT_EQ(notes_of(base).find("theta_deg is 0"), std::string::npos) << notes_of(base);
  j = base;
  j["triaxial"]["dt_factor"] = 0.7;
  EXPECT_NE(notes_of(j).find("dt is 0.968 of the critical step of an isolated pair"), std::string::npos) << notes_of(j);
}

// A wide grading's largest grain reaches past the preset's slab depth: the default is
// then the least a periodic slab allows, not a refusal to set depth_diameters by hand
// (it was "slab depth 0.00315 m is below twice the interaction reach 0.00201 m").
TEST(TriaxialReposeScenes, TheDefaultSlabHoldsAWideGradingsLargestGrain) {
  json j = repose_base();
  j["repose"].erase("depth_diameters");
  j["material"]["diameter"] = {{"grading", {{"d", {1e-4, 1e-3, 2e-3}}, {"percent_finer", {0, 5, 100}}}}};
  const Job job = parse(j);
  ASSERT_FALSE(job.tasks.empty());
  const auto& p = job.tasks[0].params;
  const double d_mean = demcal::jobs::material_from(p).grading().mean();
  EXPECT_GE(p["depth_diameters"].get<double>() * d_mean, 2.0 * (2e-3 + 0.1 * 1e-4)) << p.dump();
}

class BadTriaxialReposeJob : public ::testing::TestWithParam<Bad> {};

TEST_P(BadTriaxialReposeJob, RejectedNamingTheField) {
  json j = GetParam().repose ? repose_base() : triaxial_base();
  GetParam().mutate(j);
  const std::string msg = error_of(j);
  ASSERT_FALSE(msg.empty()) << "accepted: " << j.dump();
  EXPECT_EQ(msg.rfind(GetParam().field, 0), 0u) << "the message must begin with the field; message: " << msg;
}

INSTANTIATE_TEST_SUITE_P(TriaxialReposeScenes, BadTriaxialReposeJob, ::testing::ValuesIn(bad_cases()),
                         [](const ::testing::TestParamInfo<Bad>& i) { return std::string(i.param.name); });

// The diagnostic shear damping is absent from a task's parameters unless the job
// gives it, so that adding it left the keys of stored triaxial tasks unchanged.
TEST(TriaxialReposeScenes, ShearDampingEntersTheTaskOnlyWhenGiven) {
  const Job plain = parse(triaxial_base());
  for (const auto& t : plain.tasks) EXPECT_FALSE(t.params.contains("shear_damping")) << t.params.dump();
  json j = triaxial_base();
  j["triaxial"]["shear_damping"] = 0.2;
  const Job damped = parse(j);
  ASSERT_EQ(damped.tasks.size(), plain.tasks.size());
  for (std::size_t i = 0; i < damped.tasks.size(); ++i) {
    EXPECT_EQ(damped.tasks[i].params.at("shear_damping").get<double>(), 0.2);
    EXPECT_NE(damped.tasks[i].key, plain.tasks[i].key);
  }
}

// An optional key written as its default asks for the same work as leaving it out:
// one key, so the job reuses what the other stored; any other value is other work.
TEST(TriaxialReposeScenes, AnOptionalKeyWrittenAsItsDefaultIsTheSameTask) {
  const auto same_keys = [](const json& a, const json& b) {
    const Job x = parse(a), y = parse(b);
    if (x.tasks.size() != y.tasks.size()) return false;
    for (std::size_t i = 0; i < x.tasks.size(); ++i)
      if (x.tasks[i].key != y.tasks[i].key) return false;
    return true;
  };
  const json repose = repose_base();
  for (const auto& [key, dflt, other] : std::vector<std::tuple<std::string, json, json>>{
           {"side_walls", "periodic", "smooth"}, {"rest_profile_window", 0.5, 0.4}, {"rest_profile_tol_deg", 0.2, 0.3}}) {
    json a = repose, b = repose;
    a["repose"][key] = dflt;
    b["repose"][key] = other;
    EXPECT_TRUE(same_keys(repose, a)) << key;
    EXPECT_FALSE(same_keys(repose, b)) << key;
    EXPECT_EQ(parse(a).tasks[0].params.at(key), dflt) << "the task keeps the job's spelling";
  }
  json t = triaxial_base(), damped = triaxial_base();
  t["triaxial"]["shear_damping"] = 0.0;
  damped["triaxial"]["shear_damping"] = 0.1;
  EXPECT_TRUE(same_keys(triaxial_base(), t));
  EXPECT_FALSE(same_keys(triaxial_base(), damped));
}

// The grain density written as a factor on material.density, as the density itself,
// or left to the default (2650 kg/m^3 x 1e9 = the seed's 2.65e12) is one task: one
// key, so a job written either way reuses the other's work.
TEST(TriaxialReposeScenes, OneGrainDensityIsOneTaskHoweverItIsWritten) {
  json by_factor = triaxial_base();  // density_scale 1e9
  json by_value = triaxial_base();
  by_value["triaxial"].erase("density_scale");
  by_value["triaxial"]["scaled_density"] = 2.65e12;
  json by_default = by_value;
  by_default["triaxial"].erase("scaled_density");
  const Job a = parse(by_factor), b = parse(by_value), c = parse(by_default);
  ASSERT_EQ(a.tasks.size(), b.tasks.size());
  for (std::size_t i = 0; i < a.tasks.size(); ++i) {
    EXPECT_EQ(a.tasks[i].key, b.tasks[i].key) << a.tasks[i].params.dump() << "\n" << b.tasks[i].params.dump();
    EXPECT_EQ(a.tasks[i].key, c.tasks[i].key);
    // The task keeps the job's spelling: a grid axis and --where read it.
    EXPECT_DOUBLE_EQ(a.tasks[i].params.at("density_scale").get<double>(), 1e9);
  }
  // A different factor is different work, and a grid over the factor names its tasks.
  by_factor["triaxial"].erase("density_scale");
  by_factor["grid"]["density_scale"] = {1e8, 1e9};
  const Job grid = parse(by_factor);
  ASSERT_EQ(grid.tasks.size(), 4u);
  for (std::size_t i = 0; i < grid.tasks.size(); ++i) {
    const json& p = grid.tasks[i].params;
    if (p.at("theta_deg").get<double>() != a.tasks[0].params.at("theta_deg").get<double>()) continue;
    const bool same = p.at("density_scale").get<double>() == 1e9;
    EXPECT_EQ(grid.tasks[i].key == a.tasks[0].key, same) << p.dump();
    const std::string label = demcal::jobs::describe_task(grid, i, 7);
    EXPECT_NE(label.find(same ? "density_scale=1000000000.0" : "density_scale=100000000.0"), std::string::npos) << label;
  }
}

TEST(TriaxialReposeScenes, BaseJobsAreValid) {
  EXPECT_EQ(error_of(triaxial_base()), "");
  EXPECT_EQ(error_of(repose_base()), "");
}

// ---- one quick task of each through the runner ----------------------------------

namespace {

using demcal::test::TempDir;

// Runs a one-task job with one worker and one engine thread; returns the task's
// metrics by name, after checking it finished.
std::map<std::string, double> run_one(const json& j, double& wall_s, std::string* stored_message = nullptr) {
  TempDir d;
  const Job job = parse(j);
  EXPECT_EQ(job.tasks.size(), 1u);
  demcal::db::Store store((d.path / "demcal.db").string());
  demcal::jobs::RunOptions opt;
  opt.workers = 1;
  opt.out_dir = (d.path / "out").string();
  std::ostringstream log;
  opt.log = &log;
  const auto t0 = std::chrono::steady_clock::now();
  const auto sum = demcal::jobs::run_job(store, job, opt);
  wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_EQ(sum.done, 1) << log.str();
  EXPECT_EQ(sum.failed, 0) << log.str();
  const auto rows = store.tasks(job.name);
  EXPECT_EQ(rows.size(), 1u);
  std::map<std::string, double> m;
  if (rows.empty()) return m;
  EXPECT_EQ(rows[0].status, "done") << rows[0].error;
  if (stored_message) *stored_message = rows[0].error;
  for (const auto& [k, v] : store.metrics(rows[0].id)) m[k] = v;
  const auto art = store.artifacts(rows[0].id);
  EXPECT_EQ(art.size(), 1u);
  if (!art.empty()) {
    EXPECT_TRUE(fs::exists(art[0].second)) << art[0].second;
  }
  return m;
}

void expect_in(const std::map<std::string, double>& m, const std::string& name, double lo, double hi) {
  const auto it = m.find(name);
  ASSERT_NE(it, m.end()) << "no metric " << name;
  EXPECT_TRUE(std::isfinite(it->second)) << name;
  EXPECT_GT(it->second, lo) << name;
  EXPECT_LT(it->second, hi) << name;
}

}  // namespace

TEST(TriaxialReposeScenes, QuickTriaxialTaskRunsThroughTheRunner) {
  json j = triaxial_base();
  j["triaxial"] = {{"packing", "dense"}, {"confining_kpa", 100}, {"density_scale", 1e9}};
  j.erase("grid");
  j["fidelity"] = "quick";
  j["threads"] = 1;
  double wall = 0;
  std::string warning;
  const auto m = run_one(j, wall, &warning);
  // A finished task keeps its warnings: the quasi-static one is there exactly when
  // the stored largest inertial number exceeds the limit (1e-3).
  ASSERT_TRUE(m.count("max_inertial_number"));
  EXPECT_EQ(warning.rfind("warning: ", 0) == 0 && warning.find("not quasi-static: largest inertial number") != std::string::npos,
            m.at("max_inertial_number") > 1e-3)
      << "max I " << m.at("max_inertial_number") << ", stored: " << warning;
  std::printf("[ report   ] quick triaxial task: %.1f s wall (engine %.1f s), phi_peak %.2f, phi_cv %.2f, "
              "eps_v_final %.4f, max I %.2e\n",
              wall, m.count("wall_s") ? m.at("wall_s") : -1.0, m.count("phi_peak_deg") ? m.at("phi_peak_deg") : -1.0,
              m.count("phi_cv_deg") ? m.at("phi_cv_deg") : -1.0, m.count("eps_v_final") ? m.at("eps_v_final") : 0.0,
              m.count("max_inertial_number") ? m.at("max_inertial_number") : -1.0);
  expect_in(m, "phi_peak_deg", 15, 60);
  expect_in(m, "phi_cv_deg", 10, 50);
  expect_in(m, "phi_cv_se_deg", -1e-12, 10);
  expect_in(m, "phi_diff_deg", -5, 30);
  expect_in(m, "eps1_at_peak", 0, 0.3 + 1e-9);
  expect_in(m, "q_peak_pa", 1e4, 1e6);
  expect_in(m, "porosity_initial", 0.3, 0.5);
  expect_in(m, "porosity_final", 0.3, 0.55);
  expect_in(m, "eps_v_final", -0.3, 0.1);
  expect_in(m, "max_dilatancy_deg", -90, 90);
  expect_in(m, "max_inertial_number", 0, 1);
  expect_in(m, "coordination_final", 1, 12);
  expect_in(m, "coordination_interior_initial", 1, 12);
  expect_in(m, "coordination_interior_final", 1, 12);
  expect_in(m, "coordination_mech_interior_final", 1, 12);
  expect_in(m, "coordination_mech_initial", 1, 12);
  expect_in(m, "coordination_mech_interior_initial", 1, 12);
  expect_in(m, "lw_wall_ratio_cv", 0.3, 2.0);
  expect_in(m, "phi_peak_rows_to_end", 0, 1000);
  // The walls deprive the whole-box count of contacts; the interior is better connected.
  EXPECT_GT(m.at("coordination_interior_initial"), m.at("coordination_initial"));
  expect_in(m, "cv_effective_samples", 0.5, 1000);
  expect_in(m, "cv_dilatancy_deg", -90, 90);
  expect_in(m, "cv_drift_se_deg", 0, 90);
  expect_in(m, "wall_s", 0, 600);
  EXPECT_DOUBLE_EQ(m.at("particles"), 400);
  EXPECT_NEAR(m.at("phi_diff_deg"), m.at("phi_peak_deg") - m.at("phi_cv_deg"), 1e-9);
  // The runner's plumbing (worker process, result file, store) loses nothing: every
  // stored metric equals, bit for bit, the scene run here directly (one engine thread
  // is deterministic; JSON carries 17 digits, SQLite REAL is a double). Timings differ.
  const demcal::jobs::SceneOutput direct =
      demcal::jobs::find_scene("triaxial")->run(parse(j).tasks[0].params, demcal::jobs::RunContext{1, nullptr});
  ASSERT_TRUE(direct.outcome.ok()) << direct.outcome.message;
  std::size_t compared = 0;
  for (const auto& [name, value] : direct.metrics) {
    if (demcal::db::is_timing_metric(name)) continue;
    ASSERT_TRUE(m.count(name)) << name << " was not stored";
    if (std::isnan(value)) EXPECT_TRUE(std::isnan(m.at(name))) << name;
    else EXPECT_EQ(m.at(name), value) << name;
    ++compared;
  }
  EXPECT_GT(compared, 30u);
}

TEST(TriaxialReposeScenes, QuickReposeTaskRunsThroughTheRunner) {
  json j = repose_base();
  j["repose"] = json::object();
  j.erase("grid");
  j["fidelity"] = "quick";
  j["threads"] = 1;
  j["seed"] = 1;  // seed 7 at theta 30, eta 0.1 keeps a grain rolling past 3 s: not_settled
  double wall = 0;
  const auto m = run_one(j, wall);
  std::printf("[ report   ] quick repose task: %.1f s wall (engine %.1f s), %g grains, repose %.2f +- %.2f, "
              "steepest %.2f, runout ratio %.2f, rest at %.3f s\n",
              wall, m.count("wall_s") ? m.at("wall_s") : -1.0, m.count("particles") ? m.at("particles") : -1.0,
              m.count("repose_deg") ? m.at("repose_deg") : -1.0,
              m.count("repose_fit_err_deg") ? m.at("repose_fit_err_deg") : -1.0,
              m.count("steepest_deg") ? m.at("steepest_deg") : -1.0, m.count("runout_ratio") ? m.at("runout_ratio") : -1.0,
              m.count("time_to_rest_s") ? m.at("time_to_rest_s") : -1.0);
  expect_in(m, "repose_deg", 5, 50);
  expect_in(m, "repose_fit_err_deg", -1e-12, 10);
  expect_in(m, "steepest_deg", 5, 70);
  expect_in(m, "runout_m", 0, 0.2);
  expect_in(m, "runout_ratio", 0, 10);
  expect_in(m, "final_height_m", 0.002, 0.02);
  expect_in(m, "time_to_rest_s", 0, 1.5);
  expect_in(m, "wall_s", 0, 600);
}

// Rows every sample_steps steps replace rows every sample_strain: a grid over
// sample_strain with sample_steps set runs the same series under several keys. Noted.
TEST(TriaxialReposeScenes, ASampleStrainThatSampleStepsOverridesIsNotedUnused) {
  json j = triaxial_base();
  j["triaxial"]["sample_strain"] = 0.005;
  EXPECT_EQ(notes_of(j).find("sample_strain"), std::string::npos) << notes_of(j);  // used
  j["triaxial"]["sample_steps"] = 2000;
  EXPECT_NE(notes_of(j).find("triaxial.sample_strain (0.005) is not used: a row is taken every triaxial.sample_steps "
                             "(2000) steps of shear instead"),
            std::string::npos)
      << notes_of(j);
  j["triaxial"].erase("sample_strain");  // the default: nothing the job wrote goes unused
  EXPECT_EQ(notes_of(j).find("sample_strain"), std::string::npos) << notes_of(j);
}

// A series too coarse to locate the peak or judge the critical-state window, a step
// close enough to the critical one for a packing to jitter without settling, and
// tolerances that end a stage at once: noted before the run, which would warn or
// fail on them.
TEST(TriaxialReposeScenes, ACoarseSeriesAndAStepNearTheLimitAreNoted) {
  json j = triaxial_base();
  EXPECT_EQ(notes_of(j).find("the series takes a row"), std::string::npos) << notes_of(j);
  EXPECT_EQ(notes_of(j).find("of the critical step"), std::string::npos) << notes_of(j);
  j["triaxial"]["sample_strain"] = j["triaxial"].value("axial_strain", 0.30) / 2;
  EXPECT_NE(notes_of(j).find("about 1 in the critical-state window (eps1 0.2-0.3), fewer than 3, which cannot judge it"),
            std::string::npos)
      << notes_of(j);
  EXPECT_NE(notes_of(j).find("about 3 over the shear, fewer than 5, which cannot locate the peak"), std::string::npos)
      << notes_of(j);
  // Counted as the run records them: a row at 0 and one every 0.075 give 5 over the
  // shear and 3 in a window from 0.1 (0.15, 0.225, 0.3): nothing to note.
  j["triaxial"]["sample_strain"] = 0.075;
  j["triaxial"]["cv_from"] = 0.1;
  EXPECT_EQ(notes_of(j).find("the series takes a row"), std::string::npos) << notes_of(j);
  // Rows on both edges of a window are in it: 0.049 and 0.05, two.
  j["triaxial"]["sample_strain"] = 0.001;
  j["triaxial"]["axial_strain"] = 0.06;
  j["triaxial"]["cv_from"] = 0.049;
  j["triaxial"]["cv_to"] = 0.05;
  EXPECT_NE(notes_of(j).find("about 2 in the critical-state window (eps1 0.049-0.05)"), std::string::npos)
      << notes_of(j);
  // A shear of 0.008: its window 0.00533-0.008 holds the rows at 0.006, 0.007 and
  // 0.008 (nothing to note), but no two rows lie a dilatancy window (0.01) apart.
  j["triaxial"].erase("cv_from");
  j["triaxial"].erase("cv_to");
  j["triaxial"]["axial_strain"] = 0.008;
  EXPECT_EQ(notes_of(j).find("critical-state window"), std::string::npos) << notes_of(j);
  EXPECT_NE(notes_of(j).find("triaxial.axial_strain (0.008) is shorter than triaxial.dilatancy_window (0.01): "
                             "max_dilatancy_deg will not be measured"),
            std::string::npos)
      << notes_of(j);
  j["triaxial"].erase("axial_strain");
  j["triaxial"].erase("cv_from");
  j["triaxial"].erase("sample_strain");
  j["triaxial"]["dt_factor"] = 0.45;
  EXPECT_NE(notes_of(j).find("of the critical step of an isolated pair"), std::string::npos) << notes_of(j);
  EXPECT_NE(notes_of(j).find("above about 0.5 of it the preparation may not settle"), std::string::npos) << notes_of(j);
  EXPECT_NE(notes_of(j).find("a triaxial.dt_factor of about 0.29 keeps it at 0.4 of that limit"), std::string::npos)
      << notes_of(j);
  // Equilibrium tolerances loose enough that a stage ends at once.
  j["triaxial"].erase("dt_factor");
  j["triaxial"]["ufr_tolerance"] = 0.5;
  EXPECT_NE(notes_of(j).find("triaxial.ufr_tolerance 0.5 (the forces that far out of balance) let a preparation stage "
                             "end that far from equilibrium: the sample is not the packing asked for"),
            std::string::npos)
      << notes_of(j);
  EXPECT_EQ(notes_of(j).find("stress_tolerance 0.01"), std::string::npos) << notes_of(j);
}

// A repose column whose own weight presses deep overlaps at a scaled-down stiffness,
// and a step at the limit: noted.
TEST(TriaxialReposeScenes, AReposeStiffnessScaleTooLowAndAStepAtTheLimitAreNoted) {
  json j = repose_base();
  EXPECT_EQ(notes_of(j).find("stiffness_scale"), std::string::npos) << notes_of(j);
  EXPECT_EQ(notes_of(j).find("profile bins wide"), std::string::npos) << notes_of(j);
  // A column 4 bins wide heaps no slope to measure (the scene test's 6 mm column).
  j["repose"]["column_width"] = 0.006;
  EXPECT_NE(notes_of(j).find("repose.column_width 0.006 m is 4 profile bins wide (repose.bin_width, by default the "
                             "mean diameter): its heap's slope will span about as few, under the 6"),
            std::string::npos)
      << notes_of(j);
  j["repose"].erase("column_width");
  j["repose"]["stiffness_scale"] = 1e-6;
  EXPECT_NE(notes_of(j).find("the column's weight alone presses a grain at its foot"), std::string::npos)
      << notes_of(j);
  j["repose"].erase("stiffness_scale");
  j["repose"]["dt_factor"] = 0.72;
  EXPECT_NE(notes_of(j).find("of the critical step of an isolated pair"), std::string::npos) << notes_of(j);
}

// theta_deg defaults to 0: a repose job that leaves it out asks for frictionless
// grains, which heap nothing. Noted, and eta's uselessness with it.
TEST(TriaxialReposeScenes, AFrictionlessReposeColumnIsNoted) {
  json j = repose_base();
  EXPECT_EQ(notes_of(j).find("theta_deg is 0"), std::string::npos) << notes_of(j);
  j["material"].erase("theta_deg");
  const std::string notes = notes_of(j);
  EXPECT_NE(notes.find("task #0: material.theta_deg is 0 (also its default when a job leaves it out): frictionless grains "
                       "build no heap, they spread and may still be moving at repose.time_limit (not_settled)\n"),
            std::string::npos)  // eta 0: nothing said of it
      << notes;
  EXPECT_NE(notes.find("#1: material.theta_deg is 0"), std::string::npos) << notes;
  EXPECT_NE(notes.find("and material.eta exerts no moment without friction"), std::string::npos) << notes;
  // With a drag the grains stop, but what they make is the drag's, not a heap.
  j["repose"]["collapse_drag"] = 15.0;
  EXPECT_NE(notes_of(j).find("they spread until repose.collapse_drag stops them, and the low deposit's angle is the "
                             "drag's, not the material's"),
            std::string::npos)
      << notes_of(j);
  EXPECT_EQ(notes_of(j).find("may still be moving"), std::string::npos) << notes_of(j);
}

// min and max that cut a grading curve to half its mass: the sample is the curve's
// middle, not the sand. Noted with the shares left out; a mild cut is not.
TEST(TriaxialReposeScenes, AGradingCutToLessThanMostOfItsMassIsNoted) {
  json j = triaxial_base();
  j["material"]["diameter"] = {{"grading", {{"d", {0.0002, 0.00025, 0.00045, 0.0008, 0.001}},
                                            {"percent_finer", {0, 10, 50, 90, 100}}}},
                               {"min", 0.0004}, {"max", 0.0008}};
  EXPECT_NE(notes_of(j).find("material.diameter min and max (0.0004, 0.0008 m) keep 48"), std::string::npos)
      << notes_of(j);
  EXPECT_NE(notes_of(j).find("% is finer than min, 10% coarser than max"), std::string::npos) << notes_of(j);
  j["material"]["diameter"]["min"] = 0.00025;
  j["material"]["diameter"]["max"] = 0.001;  // 90% kept
  EXPECT_EQ(notes_of(j).find("of the grading curve's mass"), std::string::npos) << notes_of(j);
  json r = repose_base();
  r["material"]["diameter"] = j["material"]["diameter"];
  r["material"]["diameter"]["min"] = 0.0004;
  r["material"]["diameter"]["max"] = 0.0008;
  EXPECT_NE(notes_of(r).find("of the grading curve's mass"), std::string::npos) << notes_of(r);
}
