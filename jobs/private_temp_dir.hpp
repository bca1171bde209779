#pragma once
// A folder of this process's own under the system's temporary folder, made with
// mkdtemp (a fresh name, mode 0700) and removed with everything in it when the
// object goes. A fixed name such as /tmp/demcal-plot-<pid> could be made in
// advance by another local user, with links inside it pointing at the caller's
// files: whatever demcal then wrote "into" it would overwrite those files.
#include <filesystem>
#include <string>

namespace demcal::jobs {

class PrivateTempDir {
 public:
  // Throws std::runtime_error naming the folder and the reason when it cannot be made.
  explicit PrivateTempDir(const std::string& prefix);
  ~PrivateTempDir();
  PrivateTempDir(const PrivateTempDir&) = delete;
  PrivateTempDir& operator=(const PrivateTempDir&) = delete;

  const std::filesystem::path& path() const { return path_; }
  std::string file(const std::string& name) const { return (path_ / name).string(); }

 private:
  std::filesystem::path path_;
};

}  // namespace demcal::jobs
