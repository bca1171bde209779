#include "common.hpp"

#include "db/store.hpp"
#include "jobs/query.hpp"

#include <iostream>

namespace demcal::cli {

void add_query(CLI::App& app, int& exit_code) {
  auto* cmd = app.add_subcommand("query", "One row per task: parameters and metrics");
  struct Args {
    std::string db = "demcal.db", job, format = "table";
    std::vector<std::string> where, metrics;
  };
  auto a = std::make_shared<Args>();
  cmd->add_option("--db", a->db, "SQLite database")->check(kDbPath)->capture_default_str();
  cmd->add_option("--job", a->job, "only this job's tasks")->check(kNonEmpty);
  cmd->add_option("--where", a->where, "KEY=VALUE on a task parameter (or status); repeatable, and a task must match every one");
  cmd->add_option("--metrics", a->metrics, "metrics to show (comma separated), or all; default: every metric in CSV and JSON, the scene's headline metrics in a table")->delimiter(',')->check(kNonEmpty);
  cmd->add_option("--format", a->format, "table, csv or json")->capture_default_str();
  cmd->callback([a, &exit_code] {
    exit_code = guarded("", [&] {
      const jobs::Format format = jobs::parse_format(a->format);
      std::vector<jobs::Where> where;
      for (const auto& w : a->where) where.push_back(jobs::parse_where(w));
      require_db(a->db);
      db::Store store(a->db, /*read_only=*/true);
      if (!a->job.empty() && !store.find_job(a->job)) {
        std::cerr << "demcal: error: --job: no job named \"" << a->job << "\"\n";
        return kBadInput;
      }
      std::string why;
      auto rows = jobs::select_rows(store, a->job, where, &why);
      if (format == jobs::Format::json) {  // the form that gives the paths
        const jobs::ResultFilesFound f = jobs::locate_result_files(rows, a->db);
        if (f.moved > 0)
          std::cerr << "note: result files of " << f.moved << " task(s) are not where the database recorded them; "
                    << "the paths given are where they are now (the recorded path's tail, in the database's folder)\n";
        if (f.missing > 0)
          std::cerr << "note: result files of " << f.missing << " task(s) are missing: not at the recorded path, "
                    << "nor at any tail of it in the database's folder (a missing file's path is given as recorded)\n";
      }
      if (rows.empty())
        std::cerr << "demcal: no task matches" << (where.empty() ? "" : " the --where filters: " + why) << "\n";
      const int hidden = jobs::print_rows(std::cout, rows, a->metrics, format);
      if (hidden > 0)
        std::cout << "(" << hidden << " more metrics per task: --metrics all, or --format csv or json)\n";
      return kOk;
    });
  });
}

}  // namespace demcal::cli
