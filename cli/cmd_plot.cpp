#include "common.hpp"

#include "db/store.hpp"
#include "jobs/hdf5_writer.hpp"
#include "jobs/job_error.hpp"
#include "jobs/query.hpp"
#include "jobs/series_plot.hpp"

#include <filesystem>
#include <iostream>

namespace demcal::cli {

void add_plot(CLI::App& app, int& exit_code) {
  auto* cmd = app.add_subcommand("plot", "Draw a task's time series with gnuplot (PNG or SVG)");
  struct Args {
    std::string db = "demcal.db", series, x, out;
    std::vector<std::string> y;
    std::int64_t task = 0;
  };
  auto a = std::make_shared<Args>();
  cmd->add_option("TASK", a->task, "task id (the first column of demcal query)")->required();
  cmd->add_option("--db", a->db, "SQLite database")->check(kDbPath)->capture_default_str();
  cmd->add_option("--series", a->series, "series name, e.g. energy")->required();
  cmd->add_option("--x", a->x, "column for the x axis, e.g. step")->required();
  cmd->add_option("--y", a->y, "columns to draw (comma separated), e.g. total,kinetic")->required()->delimiter(',');
  cmd->add_option("--out", a->out, "output file, .png or .svg")->required()->check(kPlainPath);
  cmd->callback([a, &exit_code] {
    exit_code = guarded("", [&] {
      require_writable_file("--out", a->out);
      require_db(a->db);
      db::Store store(a->db, /*read_only=*/true);
      const auto task = store.task(a->task);
      if (!task) throw jobs::JobError("TASK", "no task with id " + std::to_string(a->task));
      const std::string h5 = jobs::task_hdf5(store, a->task);
      if (h5.empty())
        throw jobs::JobError("TASK", "task " + std::to_string(a->task) + " has no stored series (status " + task->status + ")");
      // The file must be this task's: a file at that path written for another task
      // (an output folder shared with another database) would plot the wrong run.
      if (std::filesystem::exists(h5)) {
        const std::string key = jobs::read_task_key(h5);
        if (!key.empty() && key != task->key)
          throw std::runtime_error("the HDF5 file " + h5 + " was written for another task (key " + key + ", task " +
                                   std::to_string(a->task) + " has " + task->key +
                                   "): another run overwrote it; run the task again into a folder of its own");
      }
      jobs::PlotRequest r{h5, a->series, a->x, a->y, a->out, "task " + std::to_string(a->task) + ": " + a->series};
      jobs::plot_series(r);
      std::cout << a->out << "\n";
      return kOk;
    });
  });
}

}  // namespace demcal::cli
