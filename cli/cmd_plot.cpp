#include "common.hpp"

#include "db/store.hpp"
#include "jobs/moved_results.hpp"
#include "jobs/hdf5_writer.hpp"
#include "jobs/job_error.hpp"
#include "jobs/query.hpp"
#include "jobs/series_plot.hpp"

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <iostream>

namespace demcal::cli {
namespace {

// What a series is usually looked at for, when --x or --y is left out.
struct PlotDefault {
  const char *scene, *series, *x, *y;
};
constexpr PlotDefault kDefaults[] = {
    {"triaxial", "triaxial", "eps1", "phi_mob_deg,eps_v"},
    {"collision", "energy", "step", "total,kinetic,elastic"},
    {"repose", "energy", "time", "ke_per_grain,ke_flow_per_grain"},
    {"repose", "prep", "time", "ke_per_grain,ke_flow_per_grain"},
    {"repose", "profile", "x", "h"},
};

const PlotDefault* plot_default(const std::string& scene, const std::string& series) {
  for (const auto& d : kDefaults)
    if (scene == d.scene && series == d.series) return &d;
  return nullptr;
}

std::vector<std::string> split_commas(const std::string& s) {
  std::vector<std::string> out;
  std::size_t from = 0;
  for (std::size_t at; (at = s.find(',', from)) != std::string::npos; from = at + 1) out.push_back(s.substr(from, at - from));
  out.push_back(s.substr(from));
  return out;
}

// The results moved with the database: the stored path's tail, in the database's
// folder (jobs/moved_results.hpp). The task key check below keeps it honest.
std::string moved_with_the_database(const std::string& h5, const std::string& db) {
  const std::optional<std::string> now = jobs::find_moved_result(h5, db);
  if (!now) {
    std::error_code ec;
    std::cerr << "note: the task's HDF5 file is not at " << h5 << ", nor under "
              << std::filesystem::weakly_canonical(std::filesystem::absolute(db), ec).parent_path().string()
              << " (the database's folder) at any tail of that path\n";
    return h5;
  }
  if (*now != h5)
    std::cerr << "note: the task's HDF5 file is not at " << h5 << " any more; reading " << *now
              << " (the same path's tail, in the database's folder)\n";
  return *now;
}
}  // namespace

void add_plot(CLI::App& app, int& exit_code) {
  auto* cmd = app.add_subcommand("plot", "Draw a task's time series with gnuplot (PNG or SVG)");
  struct Args {
    std::string db = "demcal.db", series, x, out;
    std::vector<std::string> y;
    std::int64_t task = 0;
  };
  auto a = std::make_shared<Args>();
  cmd->add_option("TASK", a->task, "task id (the first column of demcal query)")->required()->transform(kTaskId);
  cmd->add_option("--db", a->db, "SQLite database")->check(kDbPath)->capture_default_str();
  cmd->add_option("--series", a->series, "series name, e.g. energy")->required()->check(kNonEmpty);
  cmd->add_option("--x", a->x, "column for the x axis, e.g. step (default for the scenes' own series: triaxial eps1, energy step or time, profile x)")->check(kNonEmpty);
  cmd->add_option("--y", a->y, "columns to draw (comma separated), e.g. total,kinetic (default: triaxial phi_mob_deg,eps_v; energy total,kinetic,elastic or the kinetic energy per grain; profile h)")->delimiter(',')->check(kNonEmpty);
  cmd->add_option("--out", a->out, "output file, .png or .svg (default: taskID-SERIES.png)")->check(kPlainPath);
  cmd->callback([a, &exit_code] {
    exit_code = guarded("", [&] {
      if (a->out.empty()) {  // a file here, whatever the series is called
        std::string name = a->series;
        std::replace_if(name.begin(), name.end(), [](char c) { return !std::isalnum(static_cast<unsigned char>(c)) && c != '_' && c != '-'; }, '_');
        a->out = "task" + std::to_string(a->task) + "-" + name + ".png";
      }
      require_writable_file("--out", a->out);
      require_db(a->db);
      db::Store store(a->db, /*read_only=*/true);
      const auto task = store.task(a->task);
      if (!task) throw jobs::JobError("TASK", "no task with id " + std::to_string(a->task));
      std::string h5 = jobs::task_hdf5(store, a->task);
      if (h5.empty())
        throw jobs::JobError("TASK", "task " + std::to_string(a->task) + " has no stored series (status " + task->status + ")");
      h5 = moved_with_the_database(h5, a->db);
      // The file must be this task's: a file at that path written for another task
      // (an output folder shared with another database) would plot the wrong run.
      if (std::filesystem::exists(h5)) {
        const std::string key = jobs::read_task_key(h5);
        if (!key.empty() && key != task->key)
          throw std::runtime_error("the HDF5 file " + h5 + " was written for another task (key " + key + ", task " +
                                   std::to_string(a->task) + " has " + task->key +
                                   "): another run overwrote it; run the task again into a folder of its own");
      }
      if (a->x.empty() || a->y.empty()) {
        const PlotDefault* d = plot_default(task->scene, a->series);
        if (!d) {
          // A series the task does not have is the thing to name, not the axes.
          std::vector<std::string> names;
          try {
            if (std::filesystem::exists(h5)) names = jobs::series_names(h5);
          } catch (const std::runtime_error&) {
            // an unreadable file is plot_series' to report; the axes are asked for here
          }
          if (!names.empty()) {
            if (std::find(names.begin(), names.end(), a->series) == names.end()) {
              std::string list;
              for (const auto& n : names) list += (list.empty() ? "" : ", ") + n;
              throw jobs::JobError("--series", "task " + std::to_string(a->task) + " has no series \"" + a->series +
                                                   "\" (available: " + list + ")");
            }
          }
          throw jobs::JobError(a->x.empty() ? "--x" : "--y", "required for series \"" + a->series + "\" of a " +
                                                               task->scene + " task (no default for it)");
        }
        if (a->x.empty()) a->x = d->x;
        if (a->y.empty()) a->y = split_commas(d->y);
      }
      // A task not done (failed, or still running) wrote only part of its series: the chart says so.
      const bool not_done = task->status != "done";
      jobs::PlotRequest r{h5, a->series, a->x, a->y, a->out,
                          "task " + std::to_string(a->task) + ": " + a->series + (not_done ? " (task " + task->status + ")" : "")};
      jobs::plot_series(r);
      std::cout << a->out << "\n";
      if (not_done) {
        const std::string why = db::task_message(*task).error;
        std::cout << "note: task " << a->task << " is " << task->status
                  << (why.empty() ? std::string() : " (" + why + ")") << "; the series is what it wrote "
                  << (task->status == "failed" ? "before it stopped" : "so far") << "\n";
      }
      return kOk;
    });
  });
}

}  // namespace demcal::cli
