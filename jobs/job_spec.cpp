#include "job_spec.hpp"

#include "grid.hpp"
#include "job_error.hpp"
#include "scene_registry.hpp"
#include "scene_resolve.hpp"
#include "task_key.hpp"
#include "text_groups.hpp"
#include "validate.hpp"

#include "engine/format.hpp"

#include <cmath>
#include <algorithm>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <regex>
#include <set>
#include <iomanip>
#include <sstream>

namespace demcal::jobs {
namespace {

const char* const kTopKeys[] = {"name", "description", "scene", "material", "grid",
                                "replicas", "seed", "threads", "fidelity", "snapshots"};

// A job file nests four levels at most. Far deeper input (a generated or corrupted
// file) would overflow the stack in the recursive walks over the parsed value (the
// library's own destructor among them, 150,000 levels: a segmentation fault), so
// the parser stops at this depth.
constexpr int kMaxDepth = 64;
struct TooDeep {};

// JSON lets a key appear twice in an object and the parser keeps the last one: a
// job with "particles": 50 and, further down, "particles": 80 would run 80 without
// a word. The parser's callback sees every key; the first repeat is an error.
nlohmann::json parse_checking_duplicates(const std::string& text) {
  std::vector<std::set<std::string>> keys;  // one set per open object
  std::vector<std::string> path;            // the keys leading to the current value
  std::string repeated, where;
  auto cb = [&](int depth, nlohmann::json::parse_event_t ev, nlohmann::json& parsed) {
    using E = nlohmann::json::parse_event_t;
    if ((ev == E::object_start || ev == E::array_start) && depth >= kMaxDepth) throw TooDeep{};
    if (ev == E::object_start) keys.emplace_back();
    if (ev == E::object_end && !keys.empty()) keys.pop_back();
    if (ev == E::key && !keys.empty()) {
      const std::string k = parsed.get<std::string>();
      path.resize(static_cast<std::size_t>(std::max(depth - 1, 0)));
      if (!keys.back().insert(k).second && repeated.empty()) {
        repeated = k;
        for (const auto& p : path) where += p + ".";
      }
      path.push_back(k);
    }
    return true;
  };
  nlohmann::json j = nlohmann::json::parse(text, cb);
  if (!repeated.empty())
    throw JobError(where + repeated, "given twice in one object (JSON would keep only the last value)");
  return j;
}

// Where the number `literal` stands in `text` as a value, not inside a string (a
// description may mention it) nor as part of a longer number; npos if nowhere.
std::size_t find_number(const std::string& text, const std::string& literal) {
  bool in_string = false;
  for (std::size_t i = 0; i < text.size(); ++i) {
    const char c = text[i];
    if (in_string) {
      if (c == '\\') ++i;
      else if (c == '"') in_string = false;
      continue;
    }
    if (c == '"') {
      in_string = true;
      continue;
    }
    const bool starts = (i == 0 || std::strchr(":[, \t\r\n", text[i - 1])) && text.compare(i, literal.size(), literal) == 0;
    const std::size_t end = i + literal.size();
    if (starts && (end == text.size() || std::strchr(",]} \t\r\n", text[end]))) return i;
  }
  return std::string::npos;
}

// "LINE:COL" (from 1) of byte `at` of `text`.
std::string line_col(const std::string& text, std::size_t at) {
  std::size_t line = 1, col = 1;
  for (std::size_t i = 0; i < at && i < text.size(); ++i) {
    if (text[i] == '\n') {
      ++line;
      col = 1;
    } else {
      ++col;
    }
  }
  return std::to_string(line) + ":" + std::to_string(col);
}

nlohmann::json parse_text(const std::string& text, const std::string& source) {
  try {
    return parse_checking_duplicates(text);
  } catch (const TooDeep&) {
    throw JobError("", source + ": malformed job: objects and arrays nested more than " + std::to_string(kMaxDepth) +
                           " levels deep (a job file needs four)");
  } catch (const nlohmann::json::parse_error& e) {
    // nlohmann reports a byte offset; people want line and column.
    std::string what = e.what();
    const auto cut = what.find("parse error");
    if (cut != std::string::npos) what = what.substr(cut);
    throw JobError("", source + ":" + line_col(text, e.byte > 0 ? e.byte - 1 : 0) + ": malformed JSON: " + what);
  } catch (const nlohmann::json::exception& e) {
    // e.g. a number too large for a double (1e999): not finite, so not accepted. The
    // parser gives no offset: the number it quotes is found in the text.
    std::string what = e.what();
    if (what.rfind("[json.exception.", 0) == 0 && what.find("] ") != std::string::npos)
      what = what.substr(what.find("] ") + 2);
    const auto a = what.find('\''), b = a == std::string::npos ? a : what.find('\'', a + 1);
    const std::size_t at = b == std::string::npos ? std::string::npos : find_number(text, what.substr(a + 1, b - a - 1));
    throw JobError("", source + (at == std::string::npos ? "" : ":" + line_col(text, at)) + ": malformed JSON: " + what +
                           " (numbers must be finite)");
  }
}

std::string string_field(const nlohmann::json& j, const char* key, bool required) {
  if (!j.contains(key)) {
    if (required) throw JobError(key, "missing (required)");
    return "";
  }
  if (!j.at(key).is_string()) throw JobError(key, "expected a string, got " + describe(j.at(key)));
  return j.at(key).get<std::string>();
}

std::int64_t int_field(const nlohmann::json& j, const char* key, std::int64_t fallback, double lo, double hi) {
  if (!j.contains(key)) return fallback;
  ParamSpec s = int_param("", key, key, nullptr).at_least(lo).at_most(hi);
  return check_scalar(s, j.at(key), key).get<std::int64_t>();
}

void check_top_keys(const nlohmann::json& j, const std::string& scene) {
  std::vector<std::string> known(std::begin(kTopKeys), std::end(kTopKeys));
  known.push_back(scene);
  for (const auto& [k, v] : j.items()) {
    if (std::find(known.begin(), known.end(), k) != known.end()) continue;
    if (find_scene(k)) throw JobError(k, "section of scene \"" + k + "\", but this job's scene is \"" + scene + "\"");
    const std::string guess = closest(k, known);
    throw JobError(k, "unknown key" + (guess.empty() ? std::string() : " (did you mean \"" + guess + "\"?)"));
  }
}

const SceneDef& scene_of(const nlohmann::json& j) {
  const std::string name = string_field(j, "scene", true);
  if (const SceneDef* s = find_scene(name)) return *s;
  std::string all;
  for (const auto& n : scene_names()) all += (all.empty() ? "\"" : ", \"") + n + "\"";
  throw JobError("scene", "unknown or not yet available scene \"" + name + "\" (available: " + all + ")");
}

void read_settings(const nlohmann::json& j, Job& job) {
  job.name = string_field(j, "name", true);
  static const std::regex ok("[A-Za-z0-9][A-Za-z0-9._-]{0,99}");
  if (!std::regex_match(job.name, ok))
    throw JobError("name", "must be 1-100 characters of letters, digits, '.', '_' or '-', starting with a letter or digit");
  string_field(j, "description", false);
  job.replicas = static_cast<int>(int_field(j, "replicas", 1, 1, 10000));
  job.seed = static_cast<std::uint64_t>(int_field(j, "seed", 1, 0, 9.0e15));
  job.threads = static_cast<int>(int_field(j, "threads", 0, 1, 1024));
  job.fidelity = j.contains("fidelity") ? string_field(j, "fidelity", false) : "standard";
  if (job.fidelity != "quick" && job.fidelity != "standard" && job.fidelity != "reference")
    throw JobError("fidelity", "expected one of \"quick\", \"standard\", \"reference\", got \"" + job.fidelity + "\"");
  if (j.contains("snapshots")) {
    if (!j.at("snapshots").is_boolean()) throw JobError("snapshots", "expected true or false, got " + describe(j.at("snapshots")));
    job.snapshots = j.at("snapshots").get<bool>();
  }
}

// The critical step came out 0 s (or not a number): names the input to blame, the
// grains' density (the field the scene takes it from) when the smallest grain's mass
// or moment of inertia is out of range, else material.kn (kn / m overflows).
[[noreturn]] void refuse_zero_critical_step(const SceneDef& scene, const Task& t, const engine::StepForecast& f) {
  const nlohmann::json& p = t.params;
  std::string field = "material.density", what = "density";
  if (p.contains("scaled_density")) {
    field = scene.name + ".scaled_density";
    what = "scaled density";
  } else if (p.contains("density_scale")) {
    field = scene.name + ".density_scale";
    what = "density (material.density x density_scale)";
  }
  const double m = f.m_min;
  std::ostringstream crit;
  crit << std::setprecision(4) << f.dt_critical;
  const std::string head = "task #" + std::to_string(t.index) + ": the critical time step works out to " + crit.str() + " s: ";
  if (!(std::isnormal(m) && std::isnormal(f.inertia_min)))
    throw JobError(field, head + "the smallest grain's mass or moment of inertia is not a normal positive number "
                                 "(density x pi d_min^3 / 6, and 0.1 of that x d_min^2); check the " + what +
                                 " and the diameters");
  throw JobError("material.kn", head + "kn over the smallest grain's mass (" + engine::fmt(m, 3) +
                                    " kg) is past the largest number a double holds; check material.kn");
}

// A step past the critical one is legal in a job (a stability study charts where a
// method fails; the engine refuses the task with the mode named), but a user who
// did not mean it should hear before the run.
void note_unstable_steps(const SceneDef& scene, Job& job) {
  if (!scene.forecast) return;
  int shown = 0, more = 0;
  for (const auto& t : job.tasks) {
    const engine::StepForecast f = scene.forecast(t.params);
    // kn of 5e-324 passes "> 0" and gives an infinite step: the engine would refuse
    // every task naming dt, which the job may not even set.
    if (!(std::isfinite(f.dt) && f.dt > 0.0))
      throw JobError(t.params.contains("dt") ? "dt" : "material.kn",
                     "task #" + std::to_string(t.index) + ": the time step works out to " + std::to_string(f.dt) +
                         " s, not a finite positive number (dt_factor x sqrt(m_min / kn), with the scene's stiffness "
                         "scale): check material.kn, the stiffness scale, the diameters and the density");
    // A density of 1e-300 passes "> 0", and the smallest grain's moment of inertia
    // rounds to 0; a kn of 1e308 makes kn / m overflow: either way the critical step is
    // 0 s, and every step would read as past it, "a dt_factor of at most 0".
    if (!(std::isfinite(f.dt_critical) && f.dt_critical > 0.0)) refuse_zero_critical_step(scene, t, f);
    if (!f.exceeds()) continue;
    if (shown == 5) {
      ++more;
      continue;
    }
    std::string where;
    for (const auto& a : job.axes)
      if (t.params.contains(a)) where += (where.empty() ? "" : ", ") + a + "=" + t.params[a].dump();
    std::ostringstream os;
    os.precision(4);
    // The forecast takes the grading's extreme diameters, the run its sample's smallest
    // and largest grains: the engine's figures differ by a few per cent, hence "about".
    os << "#" << t.index << (where.empty() ? "" : " (" + where + ")") << ": dt exceeds the critical step of the "
       << f.mode << " by about " << std::setprecision(3) << f.dt / f.dt_critical << "x" << std::setprecision(4) << " ("
       << f.dt << " s against " << f.dt_critical << " s for the grading's extreme diameters)"
       << (f.refused ? "; the engine will refuse it"
                     : "; allow_unstable_dt runs it anyway, and the instability detector judges it");
    job.notes.push_back(os.str());
    ++shown;
  }
  if (more > 0) job.notes.push_back("and " + std::to_string(more) + " more task(s) past the critical step");
}

// What the settings predict a run will warn about, said once per distinct advice
// with the tasks it concerns ("all N tasks" when it is every one).
void note_advice(const SceneDef& scene, Job& job) {
  if (!scene.advice) return;
  TextGroups groups;
  for (std::size_t i = 0; i < job.tasks.size(); ++i) {
    const std::string a = scene.advice(job.tasks[i].params);
    if (!a.empty()) groups.add(a, static_cast<std::int64_t>(i));
  }
  for (std::size_t k = 0; k < groups.texts.size(); ++k) {
    const bool one = job.tasks.size() == 1;
    const std::string who = one ? "the task" : task_list(groups.tasks[k], job.tasks.size(), 8, "#");
    job.notes.push_back(who + ": " + groups.texts[k]);
  }
}

// An error a scene's resolve() blames on a parameter the grid varies points at the
// value in the list that this task took ("grid.grading[1]"), not at the section's key.
std::string axis_value_path(const SceneDef& scene, const ParamSet& set, const std::string& path,
                            const nlohmann::json& given) {
  // The error's path is the parameter's, or its parent's for a check of two fields
  // ("material.diameter: min must not exceed max" on a grid over d_min).
  auto names = [&](const ParamSpec& spec) {
    const std::string p = spec.path();
    return p == path || (p.size() > path.size() && p.compare(0, path.size(), path) == 0 && p[path.size()] == '.');
  };
  for (const auto& a : set.axes)
    for (const auto& spec : scene.params)
      if (spec.name == a.name && names(spec) && given.contains(a.name))
        for (std::size_t k = 0; k < a.values.size(); ++k)
          if (a.values[k] == given[a.name]) return a.path + "[" + std::to_string(k) + "]";
  return path;
}

void expand_tasks(const nlohmann::json& j, const SceneDef& scene, Job& job) {
  const ParamSet set = read_params(j, scene);
  for (const auto& a : set.axes) job.axes.push_back(a.name);
  job.notes = set.notes;
  const std::uint64_t n = grid_size(set, job.replicas);
  if (n > kMaxTasks)
    throw JobError("grid", "expands to " + std::string(n == grid_size_cap ? "at least " : "") + std::to_string(n) +
                               " tasks, more than the limit of " + std::to_string(kMaxTasks));
  std::vector<nlohmann::json> params = expand(set, job.replicas, job.seed);
  for (std::size_t i = 0; i < params.size(); ++i) {
    const nlohmann::json given = params[i];
    try {
      scene.resolve(params[i], job.fidelity);
    } catch (const JobError& e) {
      const std::string where = params.size() > 1 ? " (task #" + std::to_string(i) + " of the grid)" : "";
      throw JobError(axis_value_path(scene, set, e.path(), given), e.reason() + where);
    }
    Task t;
    t.index = i;
    // An optional key written as its default is the same work as one left out.
    nlohmann::json keyed = scene.key_params ? scene.key_params(params[i]) : params[i];
    for (const auto& [name, value] : scene.implied) erase_default(keyed, name, value);
    t.key = task_key(scene.name, keyed, job.snapshots);
    t.params = std::move(params[i]);
    job.tasks.push_back(std::move(t));
  }
  note_unstable_steps(scene, job);
  note_advice(scene, job);
}

}  // namespace

namespace {
// The job's settings read and checked; its tasks not yet expanded.
Job read_job(const nlohmann::json& j, const std::string& source) {
  if (!j.is_object()) throw JobError("", source + ": the job must be a JSON object, got " + describe(j));
  const SceneDef& scene = scene_of(j);
  check_top_keys(j, scene.name);
  Job job;
  job.source = source;
  job.spec = j;
  job.scene = scene.name;
  read_settings(j, job);
  return job;
}
}  // namespace

Job parse_job(const std::string& text, const std::string& source) {
  const nlohmann::json j = parse_text(text, source);
  Job job = read_job(j, source);
  expand_tasks(j, *find_scene(job.scene), job);
  return job;
}

std::uint64_t count_tasks(const std::string& text, const std::string& source) {
  const nlohmann::json j = parse_text(text, source);
  const Job job = read_job(j, source);
  return grid_size(read_params(j, *find_scene(job.scene)), job.replicas);
}

namespace {
JobError unreadable(const std::string& path) {
  std::error_code ec;
  std::string why;
  if (!std::filesystem::exists(path, ec))
    why = "no such file";
  else if (std::filesystem::is_directory(path, ec))
    why = "it is a directory";
  else
    why = "not readable (check its permissions)";
  return JobError("", "cannot read job file " + path + ": " + why);
}
}  // namespace

Job load_job_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::error_code ec;
  if (!in || std::filesystem::is_directory(path, ec)) throw unreadable(path);
  // Read at most the cap and one byte more: /dev/zero or a mistyped data file must
  // not be read until memory runs out. Pipes (process substitution) stay allowed.
  std::string text(kMaxJobFileBytes + 1, '\0');
  in.read(text.data(), static_cast<std::streamsize>(text.size()));
  if (in.bad()) throw unreadable(path);
  text.resize(static_cast<std::size_t>(in.gcount()));
  if (text.size() > kMaxJobFileBytes)
    throw JobError("", path + ": larger than " + std::to_string(kMaxJobFileBytes >> 20) +
                           " MiB, which no job file is (a grid is a list of values, not the values of every task)");
  // JSON text has no NUL byte; a parser reading up to one would ignore the rest.
  if (const auto nul = text.find('\0'); nul != std::string::npos)
    throw JobError("", path + ": a NUL byte at offset " + std::to_string(nul) + ": a job file is JSON text");
  Job job = parse_job(text, path);
  // "<job>.refine<N>" is the name `demcal fit --refine` gives its rounds of <job>: a
  // job file of that name would be read as one of them (and break <job>'s fits).
  static const std::regex reserved(".*\\.refine[0-9]+");
  if (std::regex_match(job.name, reserved))
    throw JobError("name", "\"" + job.name + "\" ends in .refine<N>, the names demcal fit --refine gives its rounds; "
                                              "choose another name");
  return job;
}

}  // namespace demcal::jobs
