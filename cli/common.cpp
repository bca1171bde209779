#include "common.hpp"

#include "db/sqlite.hpp"
#include "jobs/job_error.hpp"

#include <filesystem>
#include <iostream>

namespace demcal::cli {

int guarded(const std::string& context, const std::function<int()>& body) {
  const std::string where = context.empty() ? "" : context + ": ";
  try {
    return body();
  } catch (const jobs::JobError& e) {
    std::cerr << "demcal: error: " << (e.path().empty() ? "" : where) << e.what() << "\n";
    return kBadInput;
  } catch (const db::DbError& e) {
    std::cerr << "demcal: error: " << e.what() << "\n";
    return e.bad_input() ? kBadInput : kRuntime;
  } catch (const std::exception& e) {
    std::cerr << "demcal: error: " << e.what() << "\n";
    return kRuntime;
  }
}

std::string default_out_dir(const std::string& db_path) {
  const auto parent = std::filesystem::absolute(db_path).parent_path();
  return (parent / "demcal-out").string();
}

void require_db(const std::string& db_path) {
  if (!std::filesystem::exists(db_path))
    throw jobs::JobError("--db", "no database at " + db_path + " (run a job first, or pass --db FILE)");
}

}  // namespace demcal::cli
