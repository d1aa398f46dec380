#include "daemons/camera/v4l2_device.h"

#include <fcntl.h>
#include <libv4l2.h>
#include <poll.h>
#include <sys/mman.h>

#include <cerrno>

namespace vellum::station {
namespace {

class LibV4l2Device : public V4l2Device {
 public:
  ~LibV4l2Device() override { Close(); }
  int Open(const std::string& path) override {
    Close();
    fd_ = v4l2_open(path.c_str(), O_RDWR | O_NONBLOCK, 0);
    return fd_ < 0 ? -1 : 0;
  }
  int Ioctl(unsigned long request, void* arg) override {
    int r;
    do {
      r = v4l2_ioctl(fd_, request, arg);
    } while (r == -1 && errno == EINTR);
    return r;
  }
  void* Map(size_t length, long offset) override {
    void* start = v4l2_mmap(nullptr, length, PROT_READ | PROT_WRITE, MAP_SHARED, fd_, offset);
    return start == MAP_FAILED ? nullptr : start;
  }
  void Unmap(void* start, size_t length) override { v4l2_munmap(start, length); }
  int Poll(int timeout_ms) override {
    pollfd p{fd_, POLLIN, 0};
    int r;
    do {
      r = poll(&p, 1, timeout_ms);
    } while (r == -1 && errno == EINTR);
    if (r > 0 && (p.revents & (POLLERR | POLLHUP | POLLNVAL)) && !(p.revents & POLLIN)) {
      errno = ENODEV;  // The device went away (a UVC camera unplugged).
      return -1;
    }
    return r;
  }
  void Close() override {
    if (fd_ >= 0) v4l2_close(fd_);
    fd_ = -1;
  }

 private:
  int fd_ = -1;
};

}  // namespace

std::unique_ptr<V4l2Device> MakeLibV4l2Device() { return std::make_unique<LibV4l2Device>(); }

}  // namespace vellum::station
