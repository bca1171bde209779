#pragma once
// Who holds a running task: a runner token "host:pid:start-ticks". The process
// start time (from /proc) guards against a recycled pid making a dead runner look
// alive; a zombie counts as dead.
#include <string>

namespace demcal::jobs {

std::string runner_token();  // this process
// False when the token names a process on this host that is gone; tokens from
// other hosts are assumed alive (we cannot tell).
bool runner_alive(const std::string& token);

}  // namespace demcal::jobs
