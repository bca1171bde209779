// Mutates the example jobs at random: every mutation must either validate or be
// rejected with a JobError, never crash or throw anything else.
#include "jobs/job_error.hpp"
#include "jobs/job_spec.hpp"

#include <gtest/gtest.h>

#include <fstream>
#include <random>
#include <sstream>

using nlohmann::json;

namespace {

std::string slurp(const std::string& p) {
  std::ifstream f(p);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

// Every value slot of a JSON document, as JSON pointers.
void pointers(const json& j, const json::json_pointer& at, std::vector<json::json_pointer>& out) {
  out.push_back(at);
  if (j.is_object())
    for (const auto& [k, v] : j.items()) pointers(v, at / k, out);
  if (j.is_array())
    for (std::size_t i = 0; i < j.size(); ++i) pointers(j[i], at / i, out);
}

json random_value(std::mt19937& rng) {
  const json pool[] = {nullptr, true, false, 0, -1, 1, 0.5, -0.5, 1e300, -1e300, 1e-300, 89.999, 90, 1e12,
                       "", "x", "collision", "triaxial", json::array(), json::array({1, 2}), json::object(),
                       json::object({{"min", 1}}), 2.5, 100000, 7};
  return pool[std::uniform_int_distribution<std::size_t>(0, std::size(pool) - 1)(rng)];
}

std::string mutate_text(const std::string& text, std::mt19937& rng) {
  std::string t = text;
  const std::size_t pos = std::uniform_int_distribution<std::size_t>(0, t.size() - 1)(rng);
  switch (rng() % 4) {
    case 0: return t.substr(0, pos);                     // truncate
    case 1: t.erase(pos, 1); return t;                   // delete a byte
    case 2: t.insert(pos, 1, "{}[],:\"0e-x"[rng() % 11]); return t;  // insert a byte
    default: t[pos] = static_cast<char>(rng() % 128); return t;     // overwrite a byte
  }
}

std::string mutate_json(json j, std::mt19937& rng) {
  std::vector<json::json_pointer> ptrs;
  pointers(j, json::json_pointer(), ptrs);
  const int edits = 1 + static_cast<int>(rng() % 3);
  for (int e = 0; e < edits; ++e) {
    const auto& p = ptrs[std::uniform_int_distribution<std::size_t>(0, ptrs.size() - 1)(rng)];
    if (p.empty()) continue;
    json* v = nullptr;
    try {
      v = &j.at(p);
    } catch (const json::exception&) {
      continue;  // removed by an earlier edit
    }
    switch (rng() % 6) {
      case 0: j.at(p.parent_pointer()).is_object() ? (void)j.at(p.parent_pointer()).erase(p.back()) : (void)0; break;
      case 1: *v = random_value(rng); break;
      case 2: if (v->is_number()) *v = v->get<double>() * (rng() % 2 ? -1.0 : 1e3); break;
      case 3: if (!v->is_structured()) *v = json::array({*v, random_value(rng)}); break;
      case 4: if (j.at(p.parent_pointer()).is_object()) j.at(p.parent_pointer())[p.back() + "x"] = *v; break;
      default: if (v->is_array() && !v->empty()) v->push_back(v->back()); break;
    }
  }
  return j.dump();
}

}  // namespace

TEST(Fuzz, MutatedExamplesValidateOrFailCleanly) {
  std::vector<std::string> sources;
  for (const char* name : {"quickstart.json", "collision.json", "collision-timestep.json"})
    sources.push_back(slurp(std::string(DEMCAL_EXAMPLES_DIR) + "/" + name));
  std::mt19937 rng(12345);
  int ok = 0, rejected = 0;
  const int n = 3000;
  for (int i = 0; i < n; ++i) {
    const std::string& src = sources[static_cast<std::size_t>(i) % sources.size()];
    const std::string text = (i % 4 == 0) ? mutate_text(src, rng) : mutate_json(json::parse(src), rng);
    try {
      const auto job = demcal::jobs::parse_job(text, "fuzz.json");
      EXPECT_FALSE(job.tasks.empty());
      EXPECT_LE(job.tasks.size(), demcal::jobs::kMaxTasks);
      ++ok;
    } catch (const demcal::jobs::JobError& e) {
      EXPECT_FALSE(std::string(e.what()).empty());
      ++rejected;
    } catch (const std::exception& e) {
      ADD_FAILURE() << "unexpected " << e.what() << " for: " << text;
    }
  }
  EXPECT_GT(rejected, n / 4);
  EXPECT_GT(ok, 10);
}
