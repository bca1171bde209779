// Every bad input is rejected with a JobError whose message names the field.
#include "jobs/job_error.hpp"
#include "jobs/job_spec.hpp"

#include <algorithm>
#include <gtest/gtest.h>

#include <functional>

using demcal::jobs::JobError;
using demcal::jobs::parse_job;
using nlohmann::json;

namespace {

const char* const kBase = R"({
  "name": "v", "scene": "collision",
  "material": {"kn": 3e7, "ks": 2.7e7, "density": 2650, "b": 1.0, "theta_deg": 20, "eta": 0.1,
               "diameter": {"min": 0.001, "max": 0.002}},
  "collision": {"particles": 20, "steps": 100, "sample_every": 10, "dt_factor": 0.1},
  "grid": {"eta": [0.0, 0.2]},
  "replicas": 1, "seed": 3
})";

struct Bad {
  const char* name;
  std::function<void(json&)> mutate;  // applied to kBase
  const char* field;                  // must appear in the message
};

// Raw-text cases (the JSON itself is broken or not a job).
struct BadText {
  const char* name;
  const char* text;
  const char* expect;
};

std::string error_of(const std::string& text) {
  try {
    parse_job(text, "job.json");
  } catch (const JobError& e) {
    return e.what();
  }
  return "";
}

const std::vector<Bad>& cases() {
  static const std::vector<Bad> v = {
      {"unknown_top_key", [](json& j) { j["extra"] = 1; }, "extra"},
      {"typo_in_scene_section", [](json& j) { j["collision"]["partcles"] = 10; }, "collision.partcles"},
      {"typo_in_material", [](json& j) { j["material"]["kn_"] = 1; }, "material.kn_"},
      {"unknown_nested_key", [](json& j) { j["material"]["diameter"]["mean"] = 1; }, "material.diameter.mean"},
      {"missing_name", [](json& j) { j.erase("name"); }, "name"},
      {"missing_scene", [](json& j) { j.erase("scene"); }, "scene"},
      {"unknown_scene", [](json& j) { j["scene"] = "sandpile"; }, "scene"},
      {"section_of_another_scene", [](json& j) { j["scene"] = "triaxial"; }, "collision: section of scene \"collision\""},
      {"scene_not_string", [](json& j) { j["scene"] = 3; }, "scene"},
      {"name_not_string", [](json& j) { j["name"] = 3; }, "name"},
      {"name_with_slash", [](json& j) { j["name"] = "../evil"; }, "name"},
      {"kn_zero", [](json& j) { j["material"]["kn"] = 0; }, "material.kn"},
      {"kn_negative", [](json& j) { j["material"]["kn"] = -1; }, "material.kn"},
      {"kn_string", [](json& j) { j["material"]["kn"] = "3e7"; }, "material.kn"},
      {"ks_negative", [](json& j) { j["material"]["ks"] = -2; }, "material.ks"},
      {"ks_zero", [](json& j) { j["material"]["ks"] = 0; }, "material.ks"},
      {"density_zero", [](json& j) { j["material"]["density"] = 0; }, "material.density"},
      {"theta_90", [](json& j) { j["material"]["theta_deg"] = 90; }, "material.theta_deg"},
      {"theta_negative", [](json& j) { j["material"]["theta_deg"] = -1; }, "material.theta_deg"},
      {"theta_bool", [](json& j) { j["material"]["theta_deg"] = true; }, "material.theta_deg"},
      {"eta_negative", [](json& j) { j["material"]["eta"] = -0.1; }, "material.eta"},
      {"b_negative", [](json& j) { j["material"]["b"] = -1; }, "material.b"},
      {"b_zero", [](json& j) { j["material"]["b"] = 0; }, "material.b"},
      {"dmin_above_dmax", [](json& j) { j["material"]["diameter"] = {{"min", 0.003}, {"max", 0.002}}; }, "material.diameter"},
      {"dmin_zero", [](json& j) { j["material"]["diameter"]["min"] = 0; }, "material.diameter.min"},
      {"diameter_not_object", [](json& j) { j["material"]["diameter"] = 0.001; }, "material.diameter"},
      {"material_not_object", [](json& j) { j["material"] = {1, 2}; }, "material"},
      {"particles_fraction", [](json& j) { j["collision"]["particles"] = 20.5; }, "collision.particles"},
      {"particles_one", [](json& j) { j["collision"]["particles"] = 1; }, "collision.particles"},
      {"particles_huge", [](json& j) { j["collision"]["particles"] = 1e9; }, "collision.particles"},
      {"steps_zero", [](json& j) { j["collision"]["steps"] = 0; }, "collision.steps"},
      {"sample_every_above_steps", [](json& j) { j["collision"]["sample_every"] = 1000; }, "collision.sample_every"},
      {"solid_fraction_too_high", [](json& j) { j["collision"]["solid_fraction"] = 0.7; }, "collision.solid_fraction"},
      {"velocity_zero", [](json& j) { j["collision"]["velocity_max"] = 0; }, "collision.velocity_max"},
      {"dt_and_factor", [](json& j) { j["collision"]["dt"] = 1e-7; }, "collision.dt"},
      {"dt_factor_negative", [](json& j) { j["collision"]["dt_factor"] = -0.1; }, "collision.dt_factor"},
      {"keep_friction_number", [](json& j) { j["collision"]["keep_friction"] = 1; }, "collision.keep_friction"},
      {"null_value", [](json& j) { j["collision"]["steps"] = nullptr; }, "collision.steps"},
      {"empty_list", [](json& j) { j["material"]["theta_deg"] = json::array(); }, "material.theta_deg"},
      {"list_bad_element", [](json& j) { j["material"]["theta_deg"] = {10, 95}; }, "material.theta_deg[1]"},
      {"list_duplicate", [](json& j) { j["material"]["theta_deg"] = {10, 10}; }, "material.theta_deg[1]"},
      {"nested_list", [](json& j) { j["material"]["theta_deg"] = {{10}}; }, "material.theta_deg[0]"},
      {"grid_not_object", [](json& j) { j["grid"] = {1, 2}; }, "grid"},
      {"grid_unknown_param", [](json& j) { j["grid"]["thetadeg"] = {10}; }, "grid.thetadeg"},
      {"grid_scalar", [](json& j) { j["grid"]["eta"] = 0.1; }, "grid.eta"},
      {"grid_empty", [](json& j) { j["grid"]["eta"] = json::array(); }, "grid.eta"},
      {"grid_and_section_list", [](json& j) { j["material"]["eta"] = {0.1, 0.3}; }, "grid.eta"},
      {"material_key_in_scene_section", [](json& j) { j["collision"]["theta_deg"] = 30; },
       "collision.theta_deg: belongs in the \"material\" section"},
      {"scene_key_in_material", [](json& j) { j["material"]["particles"] = 30; },
       "material.particles: belongs in the \"collision\" section"},
      {"grid_bad_value", [](json& j) { j["grid"]["eta"] = {-1}; }, "grid.eta[0]"},
      {"grid_duplicate", [](json& j) { j["grid"]["eta"] = {0.1, 0.2, 0.1}; }, "grid.eta[2]"},
      // Apart past the 12th digit: one value to every reader of the results.
      {"grid_duplicate_to_12_digits", [](json& j) { j["grid"]["eta"] = {0.1, 0.1000000000000001}; }, "grid.eta[1]"},
      // A check of two fields (min below max) is blamed on the grid value it failed on.
      {"grid_d_min_over_max", [](json& j) { j["grid"]["d_min"] = {0.0005, 0.003}; }, "grid.d_min[1]"},
      {"replicas_zero", [](json& j) { j["replicas"] = 0; }, "replicas"},
      {"replicas_string", [](json& j) { j["replicas"] = "2"; }, "replicas"},
      {"seed_negative", [](json& j) { j["seed"] = -1; }, "seed"},
      {"threads_zero", [](json& j) { j["threads"] = 0; }, "threads"},
      {"fidelity_unknown", [](json& j) { j["fidelity"] = "fast"; }, "fidelity"},
      {"snapshots_string", [](json& j) { j["snapshots"] = "yes"; }, "snapshots"},
      {"other_scene_section", [](json& j) { j["triaxial"] = json::object(); }, "triaxial"},
      {"grid_too_large", [](json& j) { j["grid"]["particles"] = json::array(); for (int i = 2; i < 1002; ++i) j["grid"]["particles"].push_back(i); j["replicas"] = 200; }, "grid"},
  };
  return v;
}

}  // namespace

class BadJob : public ::testing::TestWithParam<Bad> {};

TEST_P(BadJob, RejectedNamingTheField) {
  json j = json::parse(kBase);
  GetParam().mutate(j);
  const std::string msg = error_of(j.dump());
  ASSERT_FALSE(msg.empty()) << "accepted: " << j.dump();
  // The message begins with the field (JobError's "path: reason"), so a short name
  // such as "seed" cannot be matched by the reason's text instead.
  EXPECT_EQ(msg.rfind(GetParam().field, 0), 0u) << "message: " << msg;
}

INSTANTIATE_TEST_SUITE_P(Validation, BadJob, ::testing::ValuesIn(cases()),
                         [](const ::testing::TestParamInfo<Bad>& i) { return std::string(i.param.name); });

TEST(Validation, BaseIsValid) { EXPECT_EQ(error_of(kBase), ""); }

TEST(Validation, MalformedJsonReportsLineAndColumn) {
  const std::string msg = error_of("{\n  \"name\": \"x\",\n  \"scene\" \"collision\"\n}");
  EXPECT_NE(msg.find("job.json:3:"), std::string::npos) << msg;
  EXPECT_NE(msg.find("malformed JSON"), std::string::npos) << msg;
}

TEST(Validation, NonFiniteNumbersRejected) {
  std::string text = kBase;
  text.replace(text.find("3e7"), 3, "1e999");
  // The parser cannot say where an overflowing number sat; it quotes the literal,
  // which is found in the text.
  const std::string msg = error_of(text);
  EXPECT_NE(msg.find("1e999"), std::string::npos) << msg;
  const std::size_t at = text.find("1e999");
  const std::size_t line = 1 + static_cast<std::size_t>(std::count(text.begin(), text.begin() + at, '\n'));
  const std::size_t col = at - text.rfind('\n', at);
  EXPECT_EQ(msg.rfind("job.json:" + std::to_string(line) + ":" + std::to_string(col) + ": ", 0), 0u) << msg;
  // The literal in a string (a description) is not the value that overflowed.
  const std::string quoted = error_of("{\"name\": \"x\", \"description\": \"kn 1e999, 1e999\", \"scene\": \"collision\",\n"
                                      "  \"material\": {\"kn\": 1e999}}");
  EXPECT_EQ(quoted.rfind("job.json:2:22: ", 0), 0u) << quoted;
  EXPECT_NE(msg.find("finite"), std::string::npos) << msg;
  EXPECT_NE(error_of("{\"name\": \"x\", \"scene\": \"collision\", \"material\": {\"kn\": NaN}}"), "");
}

TEST(Validation, AKeyGivenTwiceInOneObjectIsAnError) {
  std::string text = kBase;
  text.replace(text.find("\"steps\": 100"), 12, "\"steps\": 100, \"particles\": 30");
  const std::string msg = error_of(text);
  EXPECT_NE(msg.find("collision.particles: given twice"), std::string::npos) << msg;
  // The same key in two different objects is fine.
  EXPECT_EQ(error_of(kBase), "");
}

// A corrupted or generated file nested 150,000 deep overflowed the stack (a
// segmentation fault, no message); nesting is refused long before that.
TEST(Validation, DeepNestingIsRefusedWithAMessage) {
  for (const int depth : {70, 150000}) {
    const std::string text = "{\"name\": \"x\", \"scene\": \"collision\", \"grid\": {\"a\": " +
                             std::string(depth, '[') + std::string(depth, ']') + "}}";
    const std::string msg = error_of(text);
    EXPECT_NE(msg.find("job.json: malformed job: objects and arrays nested more than 64 levels"), std::string::npos)
        << depth << ": " << msg;
  }
  // Within the limit the nesting itself is no error (the unknown key is).
  const std::string ok = "{\"name\": \"x\", \"scene\": \"collision\", \"grid\": {\"a\": " + std::string(40, '[') +
                         std::string(40, ']') + "}}";
  EXPECT_EQ(error_of(ok).find("nested"), std::string::npos) << error_of(ok);
}

TEST(Validation, NotAnObject) { EXPECT_NE(error_of("[1, 2]").find("JSON object"), std::string::npos); }

TEST(Validation, MissingFile) {
  try {
    demcal::jobs::load_job_file("/nonexistent/job.json");
    FAIL();
  } catch (const JobError& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent/job.json"), std::string::npos);
  }
}

TEST(Validation, AGridKeyWrittenAsInItsSectionSuggestsItsFlatName) {
  json j = json::parse(kBase);
  for (const auto& [given, meant] : std::vector<std::pair<std::string, std::string>>{
           {"distribution", "size_distribution"},
           {"diameter.distribution", "size_distribution"},
           {"material.diameter.min", "d_min"},
           {"partic", "particles"}}) {
    j["grid"] = {{given, json::array({1})}};
    const std::string err = error_of(j.dump());
    EXPECT_NE(err.find("grid." + given + ": unknown parameter"), std::string::npos) << err;
    EXPECT_NE(err.find("did you mean \"" + meant + "\""), std::string::npos) << given << ": " << err;
  }
}

TEST(Validation, ASectionNestedInTheGridSaysAxesAreFlat) {
  json j = json::parse(kBase);
  j["grid"] = {{"collision", {{"dt_factor", json::array({0.05, 0.1})}}}};
  const std::string err = error_of(j.dump());
  EXPECT_NE(err.find("grid.collision: grid axes are not nested in sections"), std::string::npos) << err;
  EXPECT_NE(err.find("(\"grid\": {\"dt_factor\": [...]})"), std::string::npos) << err;
  j["grid"] = {{"material", {{"kn", json::array({1e7})}}}};
  EXPECT_NE(error_of(j.dump()).find("(\"grid\": {\"kn\": [...]})"), std::string::npos) << error_of(j.dump());
}

TEST(Validation, TypoSuggestsTheKnownKey) {
  json j = json::parse(kBase);
  j["collision"]["partcles"] = 10;
  EXPECT_NE(error_of(j.dump()).find("did you mean \"particles\""), std::string::npos);
}

// 2^53 + 1 is an integer: it is refused for its size (the field's own range), not as
// "expected an integer".
TEST(Validation, AnIntegerPastTheRangeOfADoubleIsOutOfRange) {
  json j = json::parse(kBase);
  j["seed"] = 9007199254740993ULL;
  const std::string msg = error_of(j.dump());
  EXPECT_EQ(msg.rfind("seed: must be ", 0), 0u) << msg;
  EXPECT_EQ(msg.find("expected an integer"), std::string::npos) << msg;
  j["seed"] = 1.5;
  EXPECT_EQ(error_of(j.dump()).rfind("seed: expected an integer, got 1.5", 0), 0u) << error_of(j.dump());
}
