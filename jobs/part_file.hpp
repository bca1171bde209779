#pragma once
// A file written beside its final name and renamed into place when whole: a run
// stopped mid-write, a full disk or a failed writer leaves nothing at the final path
// that looks valid, and an earlier file there stays whole. Task HDF5 files, their
// Xdmf descriptions and gnuplot's images are written this way.
#include <filesystem>
#include <stdexcept>
#include <string>

namespace demcal::jobs {

// A file could not be written or moved into place (a full disk, a folder made
// read-only or removed). For a task's HDF5 file, when the folder takes no file
// either, every later task would fail the same way after running: the runner stops.
// `folder_full`: the folder took no further file while the failed write's part was
// still on disk (a full disk or quota, or the folder removed or made read-only). Judged then, not after the part is removed: a task's own file can
// fill the disk and leave room again once deleted, and the next task would fail alike.
class OutputWriteError : public std::runtime_error {
 public:
  explicit OutputWriteError(const std::string& what, bool folder_full = false)
      : std::runtime_error(what), folder_full_(folder_full) {}
  bool folder_full() const { return folder_full_; }

 private:
  bool folder_full_;
};

// Whether `dir` takes a file of 64 KiB now (a full disk or quota, a read-only or
// vanished folder does not). The probe file is removed.
bool folder_takes_a_file(const std::filesystem::path& dir);
// Why a folder took no file, as far as the folder itself tells: gone, replaced by
// something else than a folder, or (it stands) a full disk or no permission; with
// what to do.
std::string why_folder_takes_no_file(const std::filesystem::path& dir);

class PartFile {
 public:
  // `part` is where the writer writes; by default `path` + ".part".
  explicit PartFile(std::string path);
  // A part no other process writes: `path` + ".<host>-pidns<n>-<pid>.part". For files that
  // two runs may write at once (the same task in two databases sharing a folder).
  static PartFile private_to_this_process(std::string path);
  PartFile(std::string path, std::string part);
  ~PartFile();  // removes a part that was not committed
  PartFile(const PartFile&) = delete;
  PartFile& operator=(const PartFile&) = delete;

  const std::string& path() const { return path_; }
  const std::string& part() const { return part_; }
  // Renames the part over the path. Throws OutputWriteError ("cannot move the
  // `what` into place at PATH: why") when that fails; the part is then removed with
  // the PartFile, as an uncommitted one.
  void commit(const std::string& what);

 private:
  std::string path_, part_;
  bool done_ = false;
};

}  // namespace demcal::jobs
