#pragma once

// A PostgreSQL 15 server of the test's own: a temporary data directory (initdb), started
// with pg_ctl on loopback at a free port with a private socket directory, stopped and
// removed at the end. Run as root (CI), the server runs as the unprivileged user
// `nobody` (PostgreSQL refuses root). The binaries are the ones CMake found
// (VMAP_PG_BIN); where there are none, server() is null and the test says it is skipped
// (a configure error under VMAP_REQUIRE_POSTGRES, which CI sets).

#include <doctest/doctest.h>

#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#ifndef VMAP_PG_BIN
#define VMAP_PG_BIN ""
#endif

namespace vmap::test {

class TestPostgres {
 public:
  /// Starts a server; throws when it cannot (its log is in the message).
  TestPostgres() {
    char tmpl[] = "/tmp/vmap-pg-XXXXXX";
    if (!mkdtemp(tmpl)) throw std::runtime_error("cannot make a temporary folder for the test server");
    dir_ = tmpl;
    root_ = geteuid() == 0;
    if (root_) sh("chown nobody:nogroup " + dir_.string());
    port_ = free_port();
    run(bin("initdb") + " -D " + data() + " -U vmap --auth=trust --no-sync -E UTF8 --locale=C", "initdb");
    start();
  }
  TestPostgres(const TestPostgres&) = delete;
  TestPostgres& operator=(const TestPostgres&) = delete;
  ~TestPostgres() {
    (void)std::system((as_server() + bin("pg_ctl") + " -D " + data() + " -m immediate -w stop >/dev/null 2>&1").c_str());
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }

  /// The URI of a database that exists (created per call when `db` is new).
  [[nodiscard]] std::string uri(const std::string& db = "postgres") {
    if (db != "postgres")
      run(bin("createdb") + " -h 127.0.0.1 -p " + std::to_string(port_) + " -U vmap " + db + " 2>/dev/null || true",
          "createdb");
    return "postgresql://vmap@127.0.0.1:" + std::to_string(port_) + "/" + db;
  }
  [[nodiscard]] int port() const noexcept { return port_; }

  void stop() { run(bin("pg_ctl") + " -D " + data() + " -m fast -w stop", "pg_ctl stop"); }
  void start() {
    const std::string sock = (dir_ / "socket").string();
    std::filesystem::create_directories(sock);
    if (root_) sh("chown nobody:nogroup " + sock);
    run(bin("pg_ctl") + " -D " + data() + " -l " + (dir_ / "log").string() + " -w -o \"-p " + std::to_string(port_) +
            " -k " + sock + " -c listen_addresses=127.0.0.1 -c max_connections=60\" start",
        "pg_ctl start");
  }

  /// Stops every process of this server (SIGSTOP: the postmaster and its children), so
  /// that it answers nothing while the kernel still accepts and acknowledges connections:
  /// a server that hangs. resume() lets them go on (SIGCONT).
  void pause() { signal_all(SIGSTOP); }
  void resume() { signal_all(SIGCONT); }

  /// Whether this build found PostgreSQL's server programs.
  [[nodiscard]] static bool available() { return std::string(VMAP_PG_BIN).size() > 0; }

 private:
  /// The server's processes: its postmaster (data/postmaster.pid's first line) and the
  /// processes whose parent it is.
  [[nodiscard]] std::vector<pid_t> processes() const {
    std::ifstream pid_file(dir_ / "data" / "postmaster.pid");
    long postmaster = 0;
    if (!(pid_file >> postmaster) || postmaster <= 0) throw std::runtime_error("the test server has no postmaster.pid");
    std::vector<pid_t> out{static_cast<pid_t>(postmaster)};
    for (const auto& e : std::filesystem::directory_iterator("/proc")) {
      const std::string name = e.path().filename().string();
      if (name.find_first_not_of("0123456789") != std::string::npos) continue;
      std::ifstream stat(e.path() / "stat");
      std::string line;
      if (!std::getline(stat, line)) continue;
      // pid (comm) state ppid ...: the command may hold spaces and parentheses.
      const std::size_t close = line.rfind(')');
      if (close == std::string::npos) continue;
      std::istringstream rest(line.substr(close + 1));
      std::string state;
      long parent = 0;
      if (rest >> state >> parent && parent == postmaster) out.push_back(static_cast<pid_t>(std::stol(name)));
    }
    return out;
  }
  void signal_all(int sig) const {
    for (const pid_t p : processes())
      if (::kill(p, sig) != 0 && errno != ESRCH) throw std::runtime_error("cannot signal the test server's process " + std::to_string(p));
  }

  [[nodiscard]] std::string data() const { return (dir_ / "data").string(); }
  [[nodiscard]] static std::string bin(const char* name) { return std::string(VMAP_PG_BIN) + "/" + name; }
  [[nodiscard]] std::string as_server() const {
    return root_ ? "setpriv --reuid=nobody --regid=nogroup --clear-groups " : "";
  }
  void run(const std::string& command, const char* what) {
    const std::string log = (dir_ / "command.log").string();
    if (std::system((as_server() + command + " >" + log + " 2>&1").c_str()) != 0) {
      std::ifstream in(log);
      std::stringstream text;
      text << in.rdbuf();
      std::ifstream server_log(dir_ / "log");
      text << server_log.rdbuf();
      throw std::runtime_error(std::string("the test server's ") + what + " failed: " + text.str());
    }
  }
  static void sh(const std::string& command) {
    if (std::system(command.c_str()) != 0) throw std::runtime_error("failed: " + command);
  }
  static int free_port() {
    const int fd = socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    a.sin_port = 0;
    socklen_t n = sizeof a;
    if (fd < 0 || bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0 ||
        getsockname(fd, reinterpret_cast<sockaddr*>(&a), &n) != 0)
      throw std::runtime_error("no free port on loopback");
    const int port = ntohs(a.sin_port);
    close(fd);
    return port;
  }

  std::filesystem::path dir_;
  bool root_ = false;
  int port_ = 0;
};

/// The test binary's one server, started at the first call; null (and a message saying
/// the fleet tests are skipped) where this build found no server programs.
inline TestPostgres* test_server() {
  if (!TestPostgres::available()) {
    MESSAGE("skipped: no PostgreSQL server programs were found (install postgresql-15; CI sets VMAP_REQUIRE_POSTGRES)");
    return nullptr;
  }
  static std::unique_ptr<TestPostgres> server = std::make_unique<TestPostgres>();
  return server.get();
}

}  // namespace vmap::test
