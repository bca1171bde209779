#include "query.hpp"

#include "decimal.hpp"

#include "job_error.hpp"
#include "hdf5_writer.hpp"
#include "moved_results.hpp"
#include "params.hpp"
#include "scene_registry.hpp"
#include "text_groups.hpp"

#include <stdexcept>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <iomanip>
#include <optional>
#include <set>

namespace demcal::jobs {
namespace {

nlohmann::json special(const db::TaskRow& t, const std::string& key) {
  if (key == "status") return t.status;
  if (key == "scene") return t.scene;
  if (key == "task") return t.id;
  return nullptr;
}

// What a --where key reads in a task: status, scene or id; a stored parameter; else
// the value a scene's task runs at when its parameters leave that key out.
const nlohmann::json* implied_value(const std::string& scene, const std::string& key) {
  if (const SceneDef* def = find_scene(scene))
    for (const auto& [k, v] : def->implied)
      if (k == key) return &v;
  return nullptr;
}

// A parameter as the task ran with it: stored, or implied by its scene; null if neither.
nlohmann::json param_value(const ResultRow& r, const std::string& key) {
  if (r.params.contains(key)) return r.params[key];
  const nlohmann::json* implied = implied_value(r.task.scene, key);
  return implied ? *implied : nlohmann::json();
}

// Every parameter the task ran with: the stored ones, and its scene's defaults for
// the optional keys it left out (its key leaves them out, so one work has one key).
nlohmann::json params_with_implied(const ResultRow& r) {
  nlohmann::json out = r.params.is_object() ? r.params : nlohmann::json::object();
  if (const SceneDef* def = find_scene(r.task.scene))
    for (const auto& [k, v] : def->implied)
      if (!out.contains(k)) out[k] = v;
  return out;
}

nlohmann::json where_value(const ResultRow& r, const std::string& key) {
  nlohmann::json v = special(r.task, key);
  return v.is_null() ? param_value(r, key) : v;
}

// Tables round metrics to 6 digits for reading, and parameters to 13: validate
// refuses grid values within 1e-12 of each other, and any two further apart differ in
// the 13th digit. CSV keeps every digit for further work.
std::string num(double v, bool precise = false, int digits = 6) {
  if (std::isnan(v)) return "";
  if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
  if (precise) return nlohmann::json(v).dump();
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.*g", digits, v);
  return buf;
}

std::string param_cell(const nlohmann::json& v, bool precise) {
  if (v.is_null()) return "";
  if (v.is_string()) return v.get<std::string>();
  if (v.is_number_float()) return num(v.get<double>(), precise, 13);
  return v.dump();
}

std::string csv_escape(const std::string& s) {
  if (s.find_first_of(",\"\n") == std::string::npos) return s;
  std::string out = "\"";
  for (char c : s) out += c == '"' ? std::string("\"\"") : std::string(1, c);
  return out + "\"";
}

struct Table {
  std::vector<std::string> header;
  std::vector<std::vector<std::string>> rows;
  std::vector<std::string> footnotes;  // printed under a table for reading
};

// The unfiltered listing shows every task; one whose job file was edited to leave it
// out, and that no other job shares, is listed under the job that made it.
const char* const kNoJobHoldsIt =
    "no job holds this task any more (its job file was edited to leave it out); the result is kept, and a job "
    "that asks for the same work reuses it";

// In a table for reading, a long message repeated on every row drowns the numbers:
// each distinct message gets a tag ([1], [2], ...) in the row, and is printed once
// under the table with the tasks that carry it.
void tag_messages(Table& t, const std::vector<ResultRow>& rows, std::size_t column) {
  TextGroups groups;
  for (std::size_t i = 0; i < rows.size(); ++i) {
    const db::TaskMessage m = db::task_message(rows[i].task);
    if (rows[i].task.index < 0 && m.error.empty() && m.warning.empty()) {
      const std::size_t k = groups.add(kNoJobHoldsIt, rows[i].task.id);
      t.rows[i][column] = "[" + std::to_string(k + 1) + "] note";
      continue;
    }
    if (m.error.empty() && m.warning.empty()) continue;
    const std::string text = m.error.empty() ? db::warning_message(m.warning) : m.error;
    const std::size_t k = groups.add(text, rows[i].task.id);
    // A pending or running task's text is why it went back to the queue (interrupted,
    // its runner gone): a note, not the task's failure.
    const char* kind = !m.error.empty() ? (rows[i].task.status == "failed" ? "error" : "note") : "warning";
    t.rows[i][column] = "[" + std::to_string(k + 1) + "] " + kind;
    if (rows[i].task.index < 0)  // its warning does not hide that no job holds it
      t.rows[i][column] += ", [" + std::to_string(groups.add(kNoJobHoldsIt, rows[i].task.id) + 1) + "] note";
  }
  for (std::size_t k = 0; k < groups.texts.size(); ++k) {
    std::string text = groups.texts[k];
    std::replace_if(text.begin(), text.end(), [](char ch) { return ch == '\n' || ch == '\r'; }, ' ');
    t.footnotes.push_back("[" + std::to_string(k + 1) + "] " + task_list(groups.tasks[k], rows.size()) + ": " + text);
  }
}

// A parameter whose value is a list or an object (a grading curve) would make its
// column as wide as the curve's JSON: the cell says "grading #1", and each distinct
// value is printed once under the table with its tasks, as --where takes it.
void tag_structured(Table& t, const std::vector<ResultRow>& rows, const std::vector<std::string>& params,
                    std::size_t first_column) {
  for (std::size_t c = 0; c < params.size(); ++c) {
    const std::string& key = params[c];
    TextGroups groups;
    for (std::size_t i = 0; i < rows.size(); ++i) {
      if (!rows[i].params.contains(key)) continue;
      const nlohmann::json& v = rows[i].params[key];
      if (!v.is_object() && !v.is_array()) continue;
      const std::size_t k = groups.add(v.dump(), rows[i].task.id);
      t.rows[i][first_column + c] = key + " #" + std::to_string(k + 1);
    }
    for (std::size_t k = 0; k < groups.texts.size(); ++k)
      t.footnotes.push_back(key + " #" + std::to_string(k + 1) + " (" + task_list(groups.tasks[k], rows.size()) +
                            "): " + key + "=" + groups.texts[k]);
  }
}

// The parameters of the rows (each row's params_with_implied), in the order first
// seen; only those taking more than one value (absent is a value) when varying_only. Each row's keys are walked beside
// the first row's, both in key order: one pass, no lookup per key and row.
std::vector<std::string> param_columns(const std::vector<nlohmann::json>& rows, bool varying_only) {
  if (rows.empty()) return {};
  const nlohmann::json& base = rows.front();
  std::vector<std::string> keys;
  for (auto it = base.begin(); it != base.end(); ++it) keys.push_back(it.key());
  std::set<std::string> varying;
  for (const auto& p : rows) {
    auto a = base.begin(), b = p.begin();
    while (a != base.end() || b != p.end()) {
      if (b == p.end() || (a != base.end() && a.key() < b.key())) {
        varying.insert((a++).key());
      } else if (a == base.end() || b.key() < a.key()) {
        if (std::find(keys.begin(), keys.end(), b.key()) == keys.end()) keys.push_back(b.key());
        varying.insert((b++).key());
      } else {
        if (*a != *b) varying.insert(a.key());
        ++a, ++b;
      }
    }
  }
  if (!varying_only) return keys;  // one row varies nothing: a table shows none (CSV and JSON all)
  std::vector<std::string> out;
  for (const auto& k : keys)
    if (varying.count(k)) out.push_back(k);
  return out;
}

std::vector<std::string> stored_metrics(const std::vector<ResultRow>& rows) {
  std::vector<std::string> stored;
  for (const auto& r : rows)
    for (const auto& m : r.metrics)
      if (std::find(stored.begin(), stored.end(), m.first) == stored.end()) stored.push_back(m.first);
  return stored;
}

bool asks_all(const std::vector<std::string>& asked) { return asked.size() == 1 && asked[0] == "all"; }

// The headline metrics of the rows' scenes that some row stores, in the scenes' order.
std::vector<std::string> headline_metrics(const std::vector<ResultRow>& rows, const std::vector<std::string>& stored) {
  std::vector<std::string> out;
  std::set<std::string> scenes;
  for (const auto& r : rows) {
    if (!scenes.insert(r.task.scene).second) continue;
    const SceneDef* def = find_scene(r.task.scene);
    if (!def) continue;
    for (const auto& m : def->headline)
      if (std::find(stored.begin(), stored.end(), m) != stored.end() &&
          std::find(out.begin(), out.end(), m) == out.end())
        out.push_back(m);
  }
  return out;
}

std::vector<std::string> metric_columns(const std::vector<ResultRow>& rows, const std::vector<std::string>& asked) {
  const std::vector<std::string> stored = stored_metrics(rows);
  if (asked.empty() || asks_all(asked)) return stored;
  const auto is_stored = [&](const std::string& n) { return std::find(stored.begin(), stored.end(), n) != stored.end(); };
  // A name without its unit reads the stored angle: the names map and fit take
  // (phi_peak, repose) read phi_peak_deg, repose_deg. Each column once.
  std::vector<std::string> out;
  for (const auto& a : asked) {
    const std::string name = !is_stored(a) && is_stored(a + "_deg") ? a + "_deg" : a;
    if (std::find(out.begin(), out.end(), name) == out.end()) out.push_back(name);
  }
  // A name no finished task stores is a typo, as an unknown --where key is (while
  // nothing has finished, every metric is legitimately absent).
  if (!stored.empty())
    for (const auto& a : out)
      if (!is_stored(a)) {
        std::string known, guess = closest(a, stored);
        for (const auto& k : stored) {
          known += (known.empty() ? "" : ", ") + k;
          if (k.rfind(a + "_", 0) == 0 && guess.empty()) guess = k;  // a name cut short: a stored name it begins
        }
        throw JobError("--metrics", "no task stores a metric \"" + a + "\"" +
                                        (guess.empty() ? "" : " (did you mean \"" + guess + "\"?)") + "; stored: " + known);
      }
  return out;
}

double metric_of(const ResultRow& r, const std::string& name) {
  for (const auto& m : r.metrics)
    if (m.first == name) return m.second;
  return NAN;
}

Table build(const std::vector<ResultRow>& rows, const std::vector<std::string>& metrics, bool for_reading) {
  const bool varying_only = for_reading, precise = !for_reading;
  Table t;
  std::vector<nlohmann::json> ran_with;  // a scene's defaults are columns as stored values are
  ran_with.reserve(rows.size());
  for (const auto& r : rows) ran_with.push_back(params_with_implied(r));
  const auto params = param_columns(ran_with, varying_only);
  const auto mets = metric_columns(rows, metrics);
  t.header = {"task", "job", "status"};
  t.header.insert(t.header.end(), params.begin(), params.end());
  // A metric named like a parameter (the collision scene's `steps`) gets its own
  // header, "metric.NAME": CSV readers key columns by header.
  // A table for reading has one message column (tags, the texts below it); CSV has
  // an error and a warning column, so that a script can tell them apart.
  // A task no job holds any more says so in a `note` column, present only then.
  const bool orphans = std::any_of(rows.begin(), rows.end(), [](const ResultRow& r) { return r.task.index < 0; });
  std::vector<std::string> message_columns =
      for_reading ? std::vector<std::string>{"message"} : std::vector<std::string>{"error", "warning"};
  if (!for_reading && orphans) message_columns.push_back("note");
  for (const auto& m : mets) {
    const bool taken = std::find(t.header.begin(), t.header.end(), m) != t.header.end() ||
                       std::find(message_columns.begin(), message_columns.end(), m) != message_columns.end();
    t.header.push_back(taken ? "metric." + m : m);
  }
  t.header.insert(t.header.end(), message_columns.begin(), message_columns.end());
  for (const auto& r : rows) {
    std::vector<std::string> line = {std::to_string(r.task.id), r.task.job, r.task.status};
    for (const auto& p : params) {
      const nlohmann::json v = param_value(r, p);
      line.push_back(param_cell(v, precise));
    }
    for (const auto& m : mets) line.push_back(num(metric_of(r, m), precise));
    if (for_reading) {
      line.push_back("");  // filled by tag_messages
    } else {
      const db::TaskMessage msg = db::task_message(r.task);
      line.push_back(msg.error);
      line.push_back(msg.warning);
      if (orphans) line.push_back(r.task.index < 0 ? kNoJobHoldsIt : "");
    }
    t.rows.push_back(std::move(line));
  }
  if (for_reading) {
    tag_structured(t, rows, params, 3);  // after task, job, status
    tag_messages(t, rows, t.header.size() - 1);
  }
  return t;
}

void print_table(std::ostream& out, const Table& t) {
  std::vector<std::size_t> w(t.header.size());
  for (std::size_t c = 0; c < w.size(); ++c) {
    w[c] = t.header[c].size();
    for (const auto& r : t.rows) w[c] = std::max(w[c], r[c].size());
  }
  auto line = [&](const std::vector<std::string>& cells) {
    std::string s;
    for (std::size_t c = 0; c < cells.size(); ++c) {
      s += cells[c];
      if (c + 1 < cells.size()) s += std::string(w[c] - cells[c].size() + 2, ' ');
    }
    while (!s.empty() && s.back() == ' ') s.pop_back();
    out << s << "\n";
  };
  line(t.header);
  for (const auto& r : t.rows) line(r);
  for (const auto& f : t.footnotes) out << f << "\n";
}

nlohmann::json json_number(double v) {
  if (std::isfinite(v)) return v;
  return std::isnan(v) ? nlohmann::json(nullptr) : nlohmann::json(v > 0 ? "inf" : "-inf");
}

void print_json(std::ostream& out, const std::vector<ResultRow>& rows, const std::vector<std::string>& metrics) {
  nlohmann::json arr = nlohmann::json::array();
  const auto mets = metric_columns(rows, metrics);
  for (const auto& r : rows) {
    nlohmann::json m = nlohmann::json::object();
    for (const auto& name : mets) m[name] = json_number(metric_of(r, name));
    const nlohmann::json index = r.task.index < 0 ? nlohmann::json(nullptr) : nlohmann::json(r.task.index);
    nlohmann::json o = {{"task", r.task.id},         {"job", r.task.job},     {"index", index},
                        {"scene", r.task.scene},     {"status", r.task.status}, {"attempts", r.task.attempts},
                        {"key", r.task.key},         {"params", params_with_implied(r)}, {"metrics", m},
                        {"wall_s", json_number(r.task.wall_s)}};
    const db::TaskMessage msg = db::task_message(r.task);
    if (!msg.error.empty()) o["error"] = msg.error;
    if (!msg.warning.empty()) o["warning"] = msg.warning;
    if (!r.hdf5.empty()) o["hdf5"] = r.hdf5;
    if (!r.xdmf.empty()) o["xdmf"] = r.xdmf;
    arr.push_back(std::move(o));
  }
  out << arr.dump(2) << "\n";
}

// A value no task could ever match is a typo, not an empty answer.
void check_where_value(const std::vector<ResultRow>& all, const Where& w) {
  if (w.key == "status") {
    static const char* const known[] = {"pending", "running", "done", "failed"};
    if (std::find(std::begin(known), std::end(known), w.value) == std::end(known))
      throw JobError("--where", "status is one of pending, running, done, failed; got \"" + w.value + "\"");
    return;
  }
  double d = 0.0;
  if (w.key == "task") {
    if (!parse_decimal(w.value, d) || d != std::floor(d) || d < 1)
      throw JobError("--where", "task is a task id (a whole number >= 1, as query prints); got \"" + w.value + "\"");
    return;
  }
  bool numeric = false;
  for (const auto& r : all) {
    const nlohmann::json v = where_value(r, w.key);
    if (v.is_null()) continue;
    if ((v.is_object() || v.is_array()) && nlohmann::json::parse(w.value, nullptr, false).is_discarded())
      throw JobError("--where", w.key + " is a list or object (as the job file writes it); give it as JSON, e.g. " +
                                    w.key + "='{\"d\": [...], ...}'; got \"" + w.value + "\", which is not JSON");
    if (!v.is_number()) return;
    numeric = true;
  }
  if (numeric && !parse_decimal(w.value, d))
    throw JobError("--where", w.key + " is a number in every task; got \"" + w.value + "\"");
  // A stored parameter is always finite: inf would match everything (|a - inf| <=
  // 1e-12 inf) and nan nothing.
  if (numeric && !std::isfinite(d))
    throw JobError("--where", w.key + " is a finite number in every task; got \"" + w.value + "\"");
}

// Lists and objects (a grading curve) equal element by element, numbers as --where
// compares them: 0 and 0.0, 40 and 40.0 alike.
bool same_structure(const nlohmann::json& a, const nlohmann::json& b, int depth = 0) {
  if (depth > 16) return false;
  if (a.is_number() && b.is_number()) return numbers_equal(a.get<double>(), b.get<double>());
  if (a.type() != b.type() || a.size() != b.size()) return false;
  if (a.is_array()) {
    for (std::size_t i = 0; i < a.size(); ++i)
      if (!same_structure(a[i], b[i], depth + 1)) return false;
    return true;
  }
  if (a.is_object()) {
    for (const auto& [k, x] : a.items())
      if (!b.contains(k) || !same_structure(x, b.at(k), depth + 1)) return false;
    return true;
  }
  return a == b;
}
}  // namespace

bool value_matches(const nlohmann::json& v, const std::string& want) {
  if (v.is_boolean()) return want == (v.get<bool>() ? "true" : "false");
  if (v.is_string()) return v.get<std::string>() == want;
  double d = 0.0;
  if (v.is_number()) return parse_decimal(want, d) && numbers_equal(v.get<double>(), d);
  const nlohmann::json w = nlohmann::json::parse(want, nullptr, false);
  return !w.is_discarded() && same_structure(v, w);
}

Where parse_where(const std::string& text) {
  const auto eq = text.find('=');
  if (eq == std::string::npos || eq == 0 || eq + 1 == text.size())
    throw JobError("--where", "expected KEY=VALUE, got \"" + text + "\"");
  return Where{text.substr(0, eq), text.substr(eq + 1)};
}

std::string query_hint(const std::string& db, const std::string& job) {
  return "demcal query" + (db == "demcal.db" ? std::string() : " --db " + db) + " --job " + job;
}

std::string artifact_of(const Artifacts& artifacts, const std::string& kind) {
  std::string found;
  for (const auto& [k, path] : artifacts)
    if (k == kind) found = path;
  return found;
}

namespace {
// demcal stores a task's parameters as one flat object; a database is a file anyone
// can edit, though, and parameters nested thousands of levels deep would overflow
// the stack of the recursive code that walks JSON. Deeper than this reads as corrupt.
constexpr int kMaxStoredDepth = 16;

nlohmann::json parse_stored_params(const std::string& text) {
  int depth = 0;
  const auto too_deep = [&](int d, nlohmann::json::parse_event_t e, nlohmann::json&) {
    (void)d;
    if (e == nlohmann::json::parse_event_t::object_start || e == nlohmann::json::parse_event_t::array_start) ++depth;
    if (e == nlohmann::json::parse_event_t::object_end || e == nlohmann::json::parse_event_t::array_end) --depth;
    if (depth > kMaxStoredDepth) throw std::length_error("nested too deep");
    return true;
  };
  try {
    return nlohmann::json::parse(text, too_deep);
  } catch (const std::exception&) {
    return nlohmann::json::value_t::discarded;
  }
}

// The first filter that alone matches no row, with the values its key takes.
std::string why_none_match(const std::vector<ResultRow>& all, const std::vector<Where>& where) {
  for (const auto& w : where) {
    std::vector<std::string> values;
    bool any = false;
    for (const auto& r : all) {
      const nlohmann::json v = where_value(r, w.key);
      if (v.is_null()) continue;
      any = any || value_matches(v, w.value);
      const std::string text = param_cell(v, false);
      if (std::find(values.begin(), values.end(), text) == values.end()) values.push_back(text);
    }
    if (any) continue;
    constexpr std::size_t kShown = 12;
    std::string list;
    for (std::size_t k = 0; k < values.size() && k < kShown; ++k) list += (k ? ", " : "") + values[k];
    if (values.size() > kShown) list += ", ... (" + std::to_string(values.size()) + " values)";
    return w.key + "=" + w.value + " matches no task; " + w.key + " takes " + list + " here";
  }
  return "each filter matches some task, but no task matches them all (filters on one key are not alternatives)";
}
}  // namespace

std::vector<ResultRow> select_rows(db::Store& store, const std::string& job, const std::vector<Where>& where,
                                   std::string* why_none) {
  const db::ReadSnapshot snapshot = store.snapshot();
  std::vector<ResultRow> all;
  for (auto& t : store.tasks(job)) {
    ResultRow r;
    r.params = parse_stored_params(t.params_json);
    r.task = std::move(t);
    all.push_back(std::move(r));
  }
  for (const auto& w : where) {
    const bool known = special(db::TaskRow{}, w.key) != nullptr ||
                       std::any_of(all.begin(), all.end(), [&](const ResultRow& r) { return !where_value(r, w.key).is_null(); });
    if (!known && !all.empty()) {
      std::vector<std::string> keys = {"status", "scene", "task"};
      for (const auto& r : all) {
        const nlohmann::json params = params_with_implied(r);  // a temporary would die before the loop
        for (const auto& [k, v] : params.items())
          if (std::find(keys.begin(), keys.end(), k) == keys.end()) keys.push_back(k);
      }
      std::string guess;  // theta -> theta_deg before any near spelling (eta)
      for (const auto& k : keys)
        if (guess.empty() && k.rfind(w.key + "_", 0) == 0) guess = k;
      if (guess.empty()) guess = closest(w.key, keys);
      throw JobError("--where", "no task has a parameter \"" + w.key + "\"" +
                                    (guess.empty() ? "" : " (did you mean \"" + guess + "\"?)"));
    }
    check_where_value(all, w);
  }
  std::vector<ResultRow> out;
  for (auto& r : all) {
    bool ok = true;
    for (const auto& w : where) {
      const nlohmann::json v = where_value(r, w.key);
      ok = ok && !v.is_null() && value_matches(v, w.value);
    }
    if (!ok) continue;
    r.metrics = store.metrics(r.task.id);
    const auto artifacts = store.artifacts(r.task.id);
    r.hdf5 = task_hdf5(artifacts);
    r.xdmf = artifact_of(artifacts, "xdmf");
    out.push_back(std::move(r));
  }
  if (out.empty() && why_none) *why_none = why_none_match(all, where);
  return out;
}

ResultFilesFound locate_result_files(std::vector<ResultRow>& rows, const std::string& db) {
  ResultFilesFound n;
  for (auto& r : rows) {
    bool moved = false, missing = false;
    for (std::string* path : {&r.hdf5, &r.xdmf}) {
      if (path->empty()) continue;
      std::optional<std::string> now = find_moved_result(*path, db);
      // A file found by its tail must be this task's (a folder shared with another
      // database holds files of the same name), as plot checks before drawing.
      if (now && *now != *path && path == &r.hdf5) {
        std::string key;
        try {
          key = read_task_key(*now);
        } catch (const std::exception&) {
          key = "unreadable";
        }
        if (!key.empty() && key != r.task.key) now.reset();
      }
      missing = missing || !now;
      if (now && *now != *path) {
        *path = *now;
        moved = true;
      }
    }
    n.moved += moved;
    n.missing += missing;
  }
  return n;
}

Format parse_format(const std::string& text) {
  if (text == "table") return Format::table;
  if (text == "csv") return Format::csv;
  if (text == "json") return Format::json;
  throw JobError("--format", "expected table, csv or json, got \"" + text + "\"");
}

int print_rows(std::ostream& out, const std::vector<ResultRow>& rows, const std::vector<std::string>& metrics,
               Format format) {
  if (format == Format::json) {
    print_json(out, rows, metrics);
    return 0;
  }
  if (format == Format::table && metrics.empty()) {
    // Every metric of a triaxial task is ~60 columns: a table shows the headline ones.
    const auto stored = stored_metrics(rows);
    const auto headline = headline_metrics(rows, stored);
    if (!headline.empty()) {
      print_table(out, build(rows, headline, true));
      return static_cast<int>(stored.size() - headline.size());
    }
  }
  const Table t = build(rows, metrics, format == Format::table);
  if (format == Format::table) {
    print_table(out, t);
    return 0;
  }
  for (const auto* line : {&t.header}) {
    for (std::size_t c = 0; c < line->size(); ++c) out << (c ? "," : "") << csv_escape((*line)[c]);
    out << "\n";
  }
  for (const auto& r : t.rows) {
    for (std::size_t c = 0; c < r.size(); ++c) out << (c ? "," : "") << csv_escape(r[c]);
    out << "\n";
  }
  return 0;
}

}  // namespace demcal::jobs
