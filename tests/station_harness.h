// Real processes on a real bus for the station's integration tests: starts daemons and tools
// (fork + exec, output to a file), stops them with SIGTERM and reports how they ended, and
// listens on the same LCM bus from inside the test. The test binary runs inside a private
// network namespace (scripts/netns-run.sh), so udpm traffic stays on its loopback.
#pragma once

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <lcm/lcm-cpp.hpp>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

namespace vellum::testing {

namespace fs = std::filesystem;

inline std::string ReadText(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// A bus of its own per test: the port differs, ttl=0 keeps it on this host.
inline std::string TestUrl(int port) {
  return "udpm://239.255.76.67:" + std::to_string(port) + "?ttl=0&recv_buf_size=4194304";
}

class Process {
 public:
  Process(std::vector<std::string> argv, const std::string& log_path,
          const std::vector<std::string>& env = {})
      : argv_(std::move(argv)), log_(log_path) {
    pid_ = fork();
    if (pid_ == 0) {
      FILE* f = std::freopen(log_path.c_str(), "w", stdout);
      if (f) dup2(fileno(stdout), 2);
      for (const std::string& e : env) putenv(const_cast<char*>(e.c_str()));
      std::vector<char*> args;
      for (std::string& a : argv_) args.push_back(a.data());
      args.push_back(nullptr);
      execv(args[0], args.data());
      std::perror(args[0]);
      _exit(127);
    }
  }
  ~Process() {
    if (running()) Stop();
  }
  Process(const Process&) = delete;

  bool running() {
    if (done_) return false;
    int status = 0;
    if (waitpid(pid_, &status, WNOHANG) == pid_) {
      done_ = true;
      status_ = status;
      return false;
    }
    return true;
  }
  // Waits up to timeout for the process to end; returns its exit code (or -signal, or -1000
  // when it is still running).
  int Wait(double timeout_s) {
    const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
    while (running()) {
      if (std::chrono::steady_clock::now() > end) return -1000;
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return WIFEXITED(status_) ? WEXITSTATUS(status_) : -WTERMSIG(status_);
  }
  // SIGTERM, then up to 10 s for a clean exit (SIGKILL after that); returns the exit code.
  int Stop() {
    if (running()) kill(pid_, SIGTERM);
    int code = Wait(10);
    if (code == -1000) {
      kill(pid_, SIGKILL);
      code = Wait(5);
    }
    return code;
  }
  // SIGKILL: a crash, no chance to clean up; returns once it is gone.
  void Kill() {
    if (running()) kill(pid_, SIGKILL);
    Wait(10);
    killed_ = true;
  }
  bool killed() const { return killed_; }
  std::string Output() const { return ReadText(log_); }
  const std::string& name() const { return argv_[0]; }
  pid_t pid() const { return pid_; }

 private:
  std::vector<std::string> argv_;
  std::string log_;
  pid_t pid_ = -1;
  bool done_ = false, killed_ = false;
  int status_ = 0;
};

// Handles the bus in the test until `done` holds or the timeout passes.
inline bool HandleUntil(lcm::LCM& lcm, double timeout_s, const std::function<bool()>& done) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (!done()) {
    if (std::chrono::steady_clock::now() > end) return false;
    lcm.handleTimeout(50);
  }
  return true;
}

// Subscribes a typed handler with a lambda (LCM 1.3.1's C++ API takes member functions).
template <class Msg>
class Listener {
 public:
  Listener(lcm::LCM& lcm, const std::string& channel, std::function<void(const Msg&)> f)
      : lcm_(lcm), f_(std::move(f)) {
    subscription_ = lcm.subscribe(channel, &Listener::Handle, this);
  }
  ~Listener() { lcm_.unsubscribe(subscription_); }
  Listener(const Listener&) = delete;
  void Handle(const lcm::ReceiveBuffer*, const std::string&, const Msg* msg) { f_(*msg); }

 private:
  lcm::LCM& lcm_;
  lcm::Subscription* subscription_ = nullptr;
  std::function<void(const Msg&)> f_;
};

}  // namespace vellum::testing
