#include "validate.hpp"

#include "decimal.hpp"
#include "job_error.hpp"

#include "engine/types.hpp"

#include <algorithm>
#include <sstream>

namespace demcal::jobs {
namespace {

const ParamSpec* spec_at(const SceneDef& scene, const std::string& section, const std::string& key) {
  for (const auto& s : scene.params)
    if (s.section == section && s.key == key) return &s;
  return nullptr;
}

const ParamSpec* spec_named(const SceneDef& scene, const std::string& name) {
  for (const auto& s : scene.params)
    if (s.name == name) return &s;
  return nullptr;
}

bool is_group(const SceneDef& scene, const std::string& section, const std::string& key) {
  for (const auto& s : scene.params)
    if (s.section == section && s.key.rfind(key + ".", 0) == 0) return true;
  return false;
}

std::vector<std::string> keys_in(const SceneDef& scene, const std::string& section, const std::string& prefix) {
  std::vector<std::string> out;
  for (const auto& s : scene.params) {
    if (s.section != section || s.key.rfind(prefix, 0) != 0) continue;
    const std::string rest = s.key.substr(prefix.size());
    out.push_back(rest.substr(0, rest.find('.')));
  }
  return out;
}

std::string unknown_key_reason(const std::string& key, const std::vector<std::string>& known) {
  std::string reason = "unknown key";
  const std::string guess = closest(key, known);
  if (!guess.empty()) return reason + " (did you mean \"" + guess + "\"?)";
  std::string all;
  for (const auto& k : known)
    if (all.find("\"" + k + "\"") == std::string::npos) all += (all.empty() ? "\"" : ", \"") + k + "\"";
  return reason + " (expected one of " + all + ")";
}

std::vector<nlohmann::json> check_list(const ParamSpec& spec, const nlohmann::json& list, const std::string& path) {
  if (list.empty()) throw JobError(path, "empty list: give at least one value");
  std::vector<nlohmann::json> values;
  for (std::size_t i = 0; i < list.size(); ++i) {
    const std::string at = path + "[" + std::to_string(i) + "]";
    if (list[i].is_array()) throw JobError(at, "nested lists are not allowed");
    nlohmann::json v = check_scalar(spec, list[i], at);
    for (std::size_t j = 0; j < values.size(); ++j) {
      if (values[j] == v) throw JobError(at, "duplicate value " + v.dump() + " (also at [" + std::to_string(j) + "])");
      if (values[j].is_number() && v.is_number() && numbers_equal(values[j].get<double>(), v.get<double>()))
        throw JobError(at, "duplicate value " + v.dump() + ": " + values[j].dump() + " at [" + std::to_string(j) +
                               "] is the same to 12 significant digits (query --where takes them as one)");
    }
    values.push_back(std::move(v));
  }
  return values;
}

void read_value(const ParamSpec& spec, const nlohmann::json& v, const std::string& path, ParamSet& out) {
  if (v.is_array()) {
    out.axes.push_back(Axis{spec.name, path, check_list(spec, v, path)});
  } else {
    out.base[spec.name] = check_scalar(spec, v, path);
  }
}

void read_object(const SceneDef& scene, const std::string& section, const std::string& prefix,
                 const nlohmann::json& obj, ParamSet& out) {
  const std::string here = prefix.empty() ? section : section + "." + prefix;
  if (!obj.is_object()) throw JobError(here, "expected an object, got " + describe(obj));
  for (const auto& [k, v] : obj.items()) {
    const std::string key = prefix.empty() ? k : prefix + "." + k;
    const std::string path = section + "." + key;
    if (const ParamSpec* spec = spec_at(scene, section, key)) {
      read_value(*spec, v, path, out);
    } else if (is_group(scene, section, key)) {
      read_object(scene, section, key, v, out);
    } else if (const std::string other = section == "material" ? scene.name : "material";
               prefix.empty() && (spec_at(scene, other, key) || is_group(scene, other, key))) {
      throw JobError(path, "belongs in the \"" + other + "\" section");
    } else {
      throw JobError(path, unknown_key_reason(k, keys_in(scene, section, prefix.empty() ? "" : prefix + ".")));
    }
  }
}

// A grid key written as the job file writes it in its section ("diameter.distribution",
// "distribution", "material.diameter.min") or cut short ("confining"): the flat name
// it means, or "".
std::string flat_name_for(const SceneDef& scene, const std::string& k) {
  for (const auto& s : scene.params)
    if (k == s.key || k == s.path() || k == s.key.substr(s.key.rfind('.') + 1)) return s.name;
  if (k.size() >= 3)
    for (const auto& s : scene.params)
      if (s.name.rfind(k, 0) == 0) return s.name;
  return "";
}

void read_grid(const SceneDef& scene, const nlohmann::json& grid, ParamSet& out) {
  if (!grid.is_object()) throw JobError("grid", "expected an object of parameter -> list, got " + describe(grid));
  std::vector<std::string> names;
  for (const auto& s : scene.params) names.push_back(s.name);
  for (const auto& [k, v] : grid.items()) {
    const std::string path = "grid." + k;
    const ParamSpec* spec = spec_named(scene, k);
    if (!spec) {
      // Grid axes take the flat names that `demcal validate` prints.
      const std::string flat = flat_name_for(scene, k);
      const std::string near = flat.empty() ? closest(k, names) : flat;
      // A section nested in the grid ("grid": {"repose": {"time_limit": [...]}}).
      if (v.is_object() && (k == scene.name || k == "material")) {
        std::string inner;
        for (const auto& item : v.items())
          if (!(inner = flat_name_for(scene, k + "." + item.key())).empty()) break;
        throw JobError(path, "grid axes are not nested in sections: they take the flat names `demcal validate` prints" +
                                 (inner.empty() ? std::string() : " (\"grid\": {\"" + inner + "\": [...]})") +
                                 "; a list inside the \"" + k + "\" section itself is a grid axis too");
      }
      throw JobError(path, "unknown parameter for scene \"" + scene.name + "\"" +
                               (near.empty() ? "" : " (did you mean \"" + near + "\"? grid axes take the flat names "
                                                    "`demcal validate` prints)"));
    }
    if (!v.is_array()) throw JobError(path, "expected a list of values, got " + describe(v));
    for (const auto& a : out.axes)
      if (a.name == k) throw JobError(path, "also given as a list at " + a.path);
    if (out.base.contains(k))  // the grid overrides the base value: say so, one of them is not used
      out.notes.push_back(path + " replaces " + spec->path() + " = " + out.base[k].dump());
    out.base.erase(k);
    out.axes.push_back(Axis{k, path, check_list(*spec, v, path)});
  }
}

// Angles are in degrees at the edges; a friction angle written in radians (0.52 for
// 30°) is a legal, near frictionless material that nobody calibrating sand means.
void note_radian_angles(ParamSet& out) {
  std::vector<double> given;
  std::string where = "material.theta_deg";
  for (const auto& a : out.axes)
    if (a.name == "theta_deg") {
      where = a.path;
      for (const auto& v : a.values) given.push_back(v.get<double>());
    }
  if (given.empty() && out.base.contains("theta_deg")) given.push_back(out.base["theta_deg"].get<double>());
  if (given.empty()) return;
  const double largest = *std::max_element(given.begin(), given.end());
  if (!(largest > 0.0 && largest <= engine::kPi / 2)) return;
  std::ostringstream os;
  os.precision(3);
  const bool one = given.size() == 1;
  os << where << (one ? ": the value " : ": every value is at most ") << largest << (one ? " is at most pi/2" : "")
     << ", and theta is in degrees (a near frictionless material); if " << (one ? "it is" : "these are")
     << " radians, " << largest << " rad is " << engine::rad_to_deg(largest) << " degrees";
  out.notes.push_back(os.str());
}

}  // namespace

ParamSet read_params(const nlohmann::json& job, const SceneDef& scene) {
  ParamSet out;
  for (const std::string& section : {std::string("material"), scene.name})
    if (job.contains(section)) read_object(scene, section, "", job.at(section), out);
  if (job.contains("grid")) read_grid(scene, job.at("grid"), out);
  note_radian_angles(out);
  for (const auto& s : scene.params) {
    const bool is_axis = std::any_of(out.axes.begin(), out.axes.end(), [&](const Axis& a) { return a.name == s.name; });
    if (!is_axis && !out.base.contains(s.name) && !s.fallback.is_null()) out.base[s.name] = check_scalar(s, s.fallback, s.path());
  }
  return out;
}

}  // namespace demcal::jobs
