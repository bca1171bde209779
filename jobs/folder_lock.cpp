#include "folder_lock.hpp"

#include "job_error.hpp"

#include <cerrno>
#include <cstring>
#include <fcntl.h>
#include <filesystem>
#include <string>
#include <sys/file.h>
#include <unistd.h>

namespace demcal::jobs {

FolderLock::FolderLock(const std::string& dir, const std::string& flag) {
  const std::string path = (std::filesystem::path(dir) / ".demcal-lock").string();
  fd_ = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (fd_ < 0) throw JobError(flag, "cannot open the folder's lock file " + path + ": " + std::strerror(errno));
  if (::flock(fd_, LOCK_EX | LOCK_NB) != 0) {
    const int err = errno;
    char buf[32] = {};
    const ssize_t n = ::pread(fd_, buf, sizeof buf - 1, 0);
    const std::string holder = n > 0 ? std::string(buf, static_cast<std::size_t>(n)) : std::string("?");
    ::close(fd_);
    fd_ = -1;
    if (err == EWOULDBLOCK)
      throw JobError(flag, "another demcal (pid " + holder.substr(0, holder.find('\n')) + ") is writing into " + dir +
                               ": wait for it to finish, or give this one another folder");
    throw JobError(flag, "cannot lock " + path + ": " + std::strerror(err));
  }
  // The holder's pid, for the message above.
  const std::string pid = std::to_string(::getpid()) + "\n";
  if (::ftruncate(fd_, 0) != 0 || ::pwrite(fd_, pid.data(), pid.size(), 0) < 0) {
    // Unwritten, a second study is still refused; its message shows "pid ?".
  }
}

FolderLock::~FolderLock() {
  if (fd_ >= 0) ::close(fd_);  // releases the lock
}

}  // namespace demcal::jobs
