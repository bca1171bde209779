#pragma once
// Declarations of the parameters a scene accepts: where each sits in the job file,
// its flat name in the resolved task parameters, its type and its range. The
// checks here are what makes validation strict and uniform across scenes.
#include <nlohmann/json.hpp>

#include <limits>
#include <string>
#include <vector>

namespace demcal::jobs {

// curve: a measured curve, {"d": [sizes], "percent_finer": [percents]} (the grading).
enum class ParamType { real, integer, boolean, choice, curve };

struct ParamSpec {
  std::string section;  // "material" or the scene's section
  std::string key;      // inside the section; dots for nesting ("diameter.min")
  std::string name;     // flat name: task parameters, grid keys, query --where
  ParamType type = ParamType::real;
  nlohmann::json fallback;  // default; null: none (the scene resolves it)
  double lo = -std::numeric_limits<double>::infinity();
  double hi = std::numeric_limits<double>::infinity();
  bool lo_open = false, hi_open = false;
  std::vector<std::string> choices;

  std::string path() const { return section + "." + key; }

  // Fluent range setters keep the scene tables one line per parameter.
  ParamSpec& above(double v) { lo = v; lo_open = true; return *this; }
  ParamSpec& at_least(double v) { lo = v; lo_open = false; return *this; }
  ParamSpec& below(double v) { hi = v; hi_open = true; return *this; }
  ParamSpec& at_most(double v) { hi = v; hi_open = false; return *this; }
};

ParamSpec real_param(const std::string& section, const std::string& key, const std::string& name,
                     nlohmann::json fallback);
ParamSpec int_param(const std::string& section, const std::string& key, const std::string& name,
                    nlohmann::json fallback);
ParamSpec bool_param(const std::string& section, const std::string& key, const std::string& name, bool fallback);
ParamSpec choice_param(const std::string& section, const std::string& key, const std::string& name,
                       std::vector<std::string> choices, nlohmann::json fallback);
ParamSpec curve_param(const std::string& section, const std::string& key, const std::string& name);

// Checks one scalar against its declaration and returns it in canonical form
// (reals as double, integers as int64), so equal values hash to equal keys.
// Throws JobError naming `path`.
nlohmann::json check_scalar(const ParamSpec& spec, const nlohmann::json& value, const std::string& path);

// "a number", "a string \"x\"", ...: what was found, for error messages.
std::string describe(const nlohmann::json& value);

// The closest of `candidates` to `word`, or "" when none is close: "did you mean".
std::string closest(const std::string& word, const std::vector<std::string>& candidates);

}  // namespace demcal::jobs
