#pragma once
// One writer per output folder: a study writes its charts' data and scripts under
// fixed names, so a second study into the same folder would overwrite them while
// gnuplot reads them. The lock is flock() on <dir>/.demcal-lock: the kernel drops it
// when the holder exits, however it exits, so a crashed study never blocks the next.
#include <string>

namespace demcal::jobs {

class FolderLock {
 public:
  // Takes the lock or throws JobError(flag) naming the folder and the holder (pid and
  // host). On a file system without locks it holds nothing and says why in unsupported().
  FolderLock(const std::string& dir, const std::string& flag);
  ~FolderLock();
  FolderLock(const FolderLock&) = delete;
  FolderLock& operator=(const FolderLock&) = delete;
  const std::string& unsupported() const { return unsupported_; }

 private:
  int fd_ = -1;
  std::string unsupported_;
};

}  // namespace demcal::jobs
