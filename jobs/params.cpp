#include "params.hpp"

#include "job_error.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

namespace demcal::jobs {
namespace {

std::string fmt(double v) {
  std::ostringstream os;
  os << v;
  return os.str();
}

std::string range_text(const ParamSpec& s) {
  const bool has_lo = std::isfinite(s.lo), has_hi = std::isfinite(s.hi);
  if (has_lo && has_hi)
    return std::string("in ") + (s.lo_open ? "(" : "[") + fmt(s.lo) + ", " + fmt(s.hi) + (s.hi_open ? ")" : "]");
  if (has_lo) return (s.lo_open ? "> " : ">= ") + fmt(s.lo);
  if (has_hi) return (s.hi_open ? "< " : "<= ") + fmt(s.hi);
  return "";
}

void check_range(const ParamSpec& s, double v, const std::string& path) {
  const bool low = s.lo_open ? !(v > s.lo) : !(v >= s.lo);
  const bool high = s.hi_open ? !(v < s.hi) : !(v <= s.hi);
  if (low || high) throw JobError(path, "must be " + range_text(s) + ", got " + fmt(v));
}

ParamSpec make(const std::string& section, const std::string& key, const std::string& name, ParamType t,
               nlohmann::json fallback) {
  ParamSpec s;
  s.section = section;
  s.key = key;
  s.name = name;
  s.type = t;
  s.fallback = std::move(fallback);
  return s;
}

constexpr std::size_t kMaxCurvePoints = 1000;

// The curve's shape and units; whether its points make a grading is the engine's to say.
nlohmann::json check_curve(const nlohmann::json& v, const std::string& path) {
  const char* form = "{\"d\": [sizes in m, increasing], \"percent_finer\": [percent of the mass finer, 0 ... 100]}";
  if (!v.is_object()) throw JobError(path, std::string("expected ") + form + ", got " + describe(v));
  for (const auto& [k, x] : v.items())
    if (k != "d" && k != "percent_finer") {
      const std::string guess = closest(k, {"d", "percent_finer"});
      throw JobError(path + "." + k, "unknown key" + (guess.empty() ? "" : " (did you mean \"" + guess + "\"?)") +
                                         "; expected " + form);
    }
  nlohmann::json out = nlohmann::json::object();
  for (const char* k : {"d", "percent_finer"}) {
    const std::string at = path + "." + k;
    if (!v.contains(k)) throw JobError(at, std::string("missing: a curve is ") + form);
    const nlohmann::json& list = v.at(k);
    if (!list.is_array()) throw JobError(at, "expected a list of numbers, got " + describe(list));
    if (list.size() < 2)
      throw JobError(at, "a curve needs at least two points, the smallest size (0% finer) and the largest (100%)");
    // Sampling walks the curve's pieces; a sieve analysis has tens of sizes.
    if (list.size() > kMaxCurvePoints)
      throw JobError(at, std::to_string(list.size()) + " points, more than the " + std::to_string(kMaxCurvePoints) +
                             " a grading curve may have");
    nlohmann::json vals = nlohmann::json::array();
    for (std::size_t i = 0; i < list.size(); ++i) {
      const std::string ai = at + "[" + std::to_string(i) + "]";
      if (!list[i].is_number()) throw JobError(ai, "expected a number, got " + describe(list[i]));
      const double x = list[i].get<double>();
      if (!std::isfinite(x)) throw JobError(ai, "must be finite, got " + list[i].dump());
      if (std::string(k) == "d" && !(x > 0.0 && x <= 1.0)) throw JobError(ai, "a size must be in (0, 1] m, got " + fmt(x));
      if (std::string(k) == "percent_finer" && !(x >= 0.0 && x <= 100.0))
        throw JobError(ai, "must be in [0, 100] percent, got " + list[i].dump());  // every digit: 100.0000001 is not 100
      // A sieve list written largest first would otherwise read as min above max.
      if (std::string(k) == "d" && i > 0 && !(x > list[i - 1].get<double>()))
        throw JobError(ai, "the sizes must increase (smallest sieve first), got " + list[i].dump() + " after " +
                               list[i - 1].dump());
      vals.push_back(x == 0.0 ? 0.0 : x);  // -0.0 is 0
    }
    out[k] = std::move(vals);
  }
  if (out["d"].size() != out["percent_finer"].size())
    throw JobError(path, "d has " + std::to_string(out["d"].size()) + " sizes and percent_finer " +
                             std::to_string(out["percent_finer"].size()) + " values: give one percentage per size");
  return out;
}

std::size_t edit_distance(const std::string& a, const std::string& b) {
  std::vector<std::size_t> prev(b.size() + 1), cur(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) prev[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    cur[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j)
      cur[j] = std::min({prev[j] + 1, cur[j - 1] + 1, prev[j - 1] + (a[i - 1] == b[j - 1] ? 0 : 1)});
    std::swap(prev, cur);
  }
  return prev[b.size()];
}

}  // namespace

ParamSpec real_param(const std::string& section, const std::string& key, const std::string& name,
                     nlohmann::json fallback) {
  return make(section, key, name, ParamType::real, std::move(fallback));
}
ParamSpec int_param(const std::string& section, const std::string& key, const std::string& name,
                    nlohmann::json fallback) {
  return make(section, key, name, ParamType::integer, std::move(fallback));
}
ParamSpec bool_param(const std::string& section, const std::string& key, const std::string& name, bool fallback) {
  return make(section, key, name, ParamType::boolean, fallback);
}
ParamSpec choice_param(const std::string& section, const std::string& key, const std::string& name,
                       std::vector<std::string> choices, nlohmann::json fallback) {
  ParamSpec s = make(section, key, name, ParamType::choice, std::move(fallback));
  s.choices = std::move(choices);
  return s;
}

ParamSpec curve_param(const std::string& section, const std::string& key, const std::string& name) {
  return make(section, key, name, ParamType::curve, nullptr);
}

std::string describe(const nlohmann::json& v) {
  switch (v.type()) {
    case nlohmann::json::value_t::null: return "null";
    case nlohmann::json::value_t::boolean: return std::string("the boolean ") + (v.get<bool>() ? "true" : "false");
    case nlohmann::json::value_t::string: return "the string " + v.dump();
    case nlohmann::json::value_t::array: return "a list";
    case nlohmann::json::value_t::object: return "an object";
    default: return "the number " + v.dump();
  }
}

nlohmann::json check_scalar(const ParamSpec& s, const nlohmann::json& v, const std::string& path) {
  switch (s.type) {
    case ParamType::curve: return check_curve(v, path);
    case ParamType::boolean:
      if (!v.is_boolean()) throw JobError(path, "expected true or false, got " + describe(v));
      return v;
    case ParamType::choice: {
      std::string all;
      for (const auto& c : s.choices) all += (all.empty() ? "\"" : ", \"") + c + "\"";
      if (!v.is_string()) throw JobError(path, "expected one of " + all + ", got " + describe(v));
      if (std::find(s.choices.begin(), s.choices.end(), v.get<std::string>()) == s.choices.end())
        throw JobError(path, "expected one of " + all + ", got " + v.dump());
      return v;
    }
    case ParamType::integer: {
      if (!v.is_number()) throw JobError(path, "expected an integer, got " + describe(v));
      const double d = v.get<double>();
      if (!std::isfinite(d)) throw JobError(path, "must be finite, got " + v.dump());
      if (v.is_number_float() && std::floor(d) != d) throw JobError(path, "expected an integer, got " + v.dump());
      check_range(s, d, path);  // the parameter's own range first: it is the one to meet
      // Past 9e15 a double no longer holds every integer: an integer, but out of range.
      if (std::abs(d) > 9.0e15) throw JobError(path, "must be at most 9e15 in magnitude, got " + v.dump());
      return v.is_number_float() ? nlohmann::json(static_cast<std::int64_t>(d)) : nlohmann::json(v.get<std::int64_t>());
    }
    case ParamType::real: {
      if (!v.is_number()) throw JobError(path, "expected a number, got " + describe(v));
      const double d = v.get<double>();
      if (!std::isfinite(d)) throw JobError(path, "must be finite, got " + v.dump());
      check_range(s, d, path);
      return nlohmann::json(d == 0.0 ? 0.0 : d);  // -0.0 is 0: one task key for one value
    }
  }
  return v;
}

std::string closest(const std::string& word, const std::vector<std::string>& candidates) {
  std::string best;
  std::size_t best_d = 3;  // more than two edits apart is not a typo
  for (const auto& c : candidates) {
    const std::size_t d = edit_distance(word, c);
    if (d < best_d) {
      best_d = d;
      best = c;
    }
  }
  if (best_d <= 1) return best;
  // A name without its unit or part ("theta" for "theta_deg", "confining" for
  // "confining_kpa"), when one key alone reads so ("phi" would be several): closer
  // than a typo two edits away ("theta" is two from "eta").
  std::vector<std::string> prefixed;
  if (word.size() >= 3)
    for (const auto& c : candidates)
      if (c.size() > word.size() && c.compare(0, word.size(), word) == 0 &&
          (c[word.size()] == '_' || c[word.size()] == '.') &&
          std::find(prefixed.begin(), prefixed.end(), c) == prefixed.end())
        prefixed.push_back(c);
  if (prefixed.size() == 1) return prefixed.front();
  return best;
}

}  // namespace demcal::jobs
