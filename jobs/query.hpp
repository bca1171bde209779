#pragma once
// Reading results back: one row per task with its parameters and metrics,
// filtered by parameter values, printed as an aligned table, CSV or JSON.
#include "db/store.hpp"

#include <nlohmann/json.hpp>
#include <ostream>
#include <string>
#include <vector>

namespace demcal::jobs {

struct Where {
  std::string key, value;
};
// "theta_deg=30" -> {theta_deg, 30}; throws JobError("--where", ...) when malformed.
Where parse_where(const std::string& text);
// Whether a stored parameter value equals the text of a --where (numbers to 1e-12).
bool value_matches(const nlohmann::json& v, const std::string& want);
// "demcal query [--db DB] --job JOB": the command that shows a job's tasks, for hints
// in messages; names the database unless it is the default, or it would query another.
std::string query_hint(const std::string& db, const std::string& job);

struct ResultRow {
  db::TaskRow task;
  nlohmann::json params;
  std::vector<std::pair<std::string, double>> metrics;
  std::string hdf5;  // the task's HDF5 file, "" when it has none
  std::string xdmf;  // its snapshots' Xdmf description for ParaView, "" when none were taken
};

// Keys: any task parameter, or status, scene, task (the id). Numbers compare as
// numbers (30 matches 30.0), booleans as true/false. A key no task has is an error.
// When no row matches, `why_none` (if given) receives the first filter that matches
// no task on its own and the values its key takes ("eta takes 0, 0.1, 0.3 here").
std::vector<ResultRow> select_rows(db::Store& store, const std::string& job, const std::vector<Where>& where,
                                   std::string* why_none = nullptr);

// The rows' HDF5 and Xdmf paths where the files are now: a database moved together
// with its results keeps the old absolute paths (jobs/moved_results.hpp). Counts the
// tasks whose files were found elsewhere, and those whose files are nowhere.
struct ResultFilesFound {
  int moved = 0, missing = 0;
};
ResultFilesFound locate_result_files(std::vector<ResultRow>& rows, const std::string& db);

// A task's file of one kind ("hdf5", "xdmf") as the database records it, "" when it has none.
using Artifacts = std::vector<std::pair<std::string, std::string>>;  // kind, path (Store::artifacts)
std::string artifact_of(const Artifacts& artifacts, const std::string& kind);
inline std::string task_hdf5(const Artifacts& artifacts) { return artifact_of(artifacts, "hdf5"); }
inline std::string task_hdf5(db::Store& store, std::int64_t task_id) { return task_hdf5(store.artifacts(task_id)); }

enum class Format { table, csv, json };
Format parse_format(const std::string& text);

// metrics empty: every metric any row has, except in table form, which shows the
// headline metrics of the rows' scenes (SceneDef::headline) and returns how many
// stored metrics it left out (0 otherwise); {"all"}: every metric in every form. In
// table form only the parameters that vary between rows are shown (all of them in
// CSV and JSON).
int print_rows(std::ostream& out, const std::vector<ResultRow>& rows, const std::vector<std::string>& metrics,
               Format format);

}  // namespace demcal::jobs
