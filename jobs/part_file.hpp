#pragma once
// A file written beside its final name and renamed into place when whole: a run
// stopped mid-write, a full disk or a failed writer leaves nothing at the final path
// that looks valid, and an earlier file there stays whole. Task HDF5 files, their
// Xdmf descriptions and gnuplot's images are written this way.
#include <string>

namespace demcal::jobs {

class PartFile {
 public:
  // `part` is where the writer writes; by default `path` + ".part".
  explicit PartFile(std::string path);
  PartFile(std::string path, std::string part);
  ~PartFile();  // removes a part that was not committed
  PartFile(const PartFile&) = delete;
  PartFile& operator=(const PartFile&) = delete;

  const std::string& path() const { return path_; }
  const std::string& part() const { return part_; }
  // Renames the part over the path. Throws std::runtime_error ("cannot move the
  // `what` into place at PATH: why") when that fails; the part is then removed with
  // the PartFile, as an uncommitted one.
  void commit(const std::string& what);

 private:
  std::string path_, part_;
  bool done_ = false;
};

}  // namespace demcal::jobs
