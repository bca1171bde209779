#pragma once
// A job file is wrong. `path` names the place in the JSON (e.g. "collision.particles",
// "grid.theta_deg[2]"); the CLI turns it into exit code 2.
#include <stdexcept>
#include <string>

namespace demcal::jobs {

class JobError : public std::invalid_argument {
 public:
  JobError(std::string path, std::string reason)
      : std::invalid_argument(path.empty() ? reason : path + ": " + reason),
        path_(std::move(path)),
        reason_(std::move(reason)) {}
  const std::string& path() const { return path_; }
  const std::string& reason() const { return reason_; }

 private:
  std::string path_, reason_;
};

}  // namespace demcal::jobs
