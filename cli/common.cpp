#include "common.hpp"

#include "db/sqlite.hpp"
#include "jobs/job_error.hpp"

#include <filesystem>
#include <iostream>
#include <unistd.h>

namespace demcal::cli {

int guarded(const std::string& context, const std::function<int()>& body) {
  const std::string where = context.empty() ? "" : context + ": ";
  try {
    return body();
  } catch (const jobs::JobError& e) {
    // A command-line flag's fault is not the job file's: no file name before it.
    const bool flag = e.path().rfind("--", 0) == 0;
    std::cerr << "demcal: error: " << (e.path().empty() || flag ? "" : where) << e.what() << "\n";
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

void require_writable_dir(const std::string& flag, const std::string& dir) {
  if (dir.empty()) throw jobs::JobError(flag, "empty path");
  // The nearest folder that exists must take new entries; nothing is created here.
  std::filesystem::path p = std::filesystem::absolute(dir);
  while (!std::filesystem::exists(p) && p.has_parent_path() && p.parent_path() != p) p = p.parent_path();
  if (!std::filesystem::is_directory(p)) throw jobs::JobError(flag, p.string() + " is not a folder (for " + dir + ")");
  if (::access(p.c_str(), W_OK) != 0) throw jobs::JobError(flag, "cannot write into the folder " + p.string() + " (for " + dir + ")");
}

void require_writable_file(const std::string& flag, const std::string& file) {
  if (file.empty()) throw jobs::JobError(flag, "empty path");
  const auto parent = std::filesystem::absolute(file).parent_path();
  if (!std::filesystem::is_directory(parent))
    throw jobs::JobError(flag, "the folder " + parent.string() + " does not exist (for " + file + ")");
  if (::access(parent.c_str(), W_OK) != 0)
    throw jobs::JobError(flag, "cannot write into the folder " + parent.string() + " (for " + file + ")");
  if (std::filesystem::is_directory(file)) throw jobs::JobError(flag, file + " is a folder, not a file");
}

void print_notes(const std::string& job_file, const std::vector<std::string>& notes) {
  for (const auto& n : notes) std::cerr << "demcal: note: " << job_file << ": " << n << "\n";
}

}  // namespace demcal::cli
