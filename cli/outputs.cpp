// Output claims, --force, and the SIGINT / SIGTERM cleanup thread (contract in cli/outputs.h).
#include "cli/outputs.h"

#include <pthread.h>
#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cerrno>
#include <cstdio>
#include <filesystem>
#include <mutex>
#include <regex>
#include <thread>

namespace btfc::cli {
namespace {

namespace fs = std::filesystem;

struct Claim {
  fs::path out;       // as the user gave it, trailing slashes removed
  fs::path aside;     // where --force moved the existing output ("" = nothing moved)
  bool existed = false;
};

std::mutex g_mutex;
std::vector<Claim> g_claims;
std::vector<fs::path> g_work_dirs;
bool g_force = false;

std::string pid_text() { return std::to_string(::getpid()); }

// Every extension that names a file type btfc knows; a path ending in another (or none) may be
// a directory.
bool is_file_ext(const std::string& e) {
  static const char* k[] = {".btfc", ".btf", ".png", ".exr", ".jpg", ".jpeg", ".tif", ".tiff", ".hdr", ".bmp",
                            ".json", ".csv", ".txt", ".bsvtf", ".ktx2", ".frag", ".glsl"};
  return std::find(std::begin(k), std::end(k), e) != std::end(k);
}

std::string lower(std::string s) {
  for (char& c : s) c = char(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

fs::path strip_slashes(std::string p) {
  while (p.size() > 1 && p.back() == '/') p.pop_back();
  return fs::path(p);
}

// True when `inner` (canonical) lies inside directory `outer` (canonical).
bool inside(const fs::path& outer, const fs::path& inner) {
  auto o = outer.begin(), i = inner.begin();
  for (; o != outer.end(); ++o, ++i)
    if (i == inner.end() || *o != *i) return false;
  return true;
}

std::string join(const std::vector<std::string>& v) {
  std::string s;
  for (size_t i = 0; i < v.size(); ++i) s += (i ? (i + 1 == v.size() ? " or " : ", ") : "") + v[i];
  return s;
}

// Removes the temporaries the writers make beside `out` for this process.
void remove_temps(const fs::path& out) {
  std::error_code ec;
  const fs::path parent = out.parent_path().empty() ? fs::path(".") : out.parent_path();
  const std::string name = out.filename().string();
  const std::string tmp = name + ".tmp-" + pid_text(), exp = name + ".tmp-export", work = ".btfc-work-" + pid_text() + ".btf";
  for (fs::directory_iterator it(parent, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string n = it->path().filename().string();
    if (n.rfind(tmp, 0) == 0 || n == exp || n == work) fs::remove_all(it->path(), ec);
  }
}

// Undoes one claim of a run that did not succeed: a new output goes, a moved-aside one returns.
void undo(const Claim& c) {
  std::error_code ec;
  remove_temps(c.out);
  if (!c.existed) fs::remove_all(c.out, ec);
  if (!c.aside.empty() && fs::symlink_status(c.aside, ec).type() != fs::file_type::not_found) {
    fs::remove_all(c.out, ec);
    fs::rename(c.aside, c.out, ec);
  }
}

// The handler only writes the signal number into a pipe (async-signal-safe), whichever thread
// the kernel picked (OpenBLAS starts its threads before main); the cleanup thread reads it.
int g_pipe[2] = {-1, -1};

void on_signal(int sig) {
  const unsigned char b = static_cast<unsigned char>(sig);
  if (::write(g_pipe[1], &b, 1) < 0) _exit(128 + sig);
}

void wait_for_signals() {
  unsigned char b = 0;
  while (::read(g_pipe[0], &b, 1) != 1) {
    if (errno != EINTR) return;
  }
  const int sig = b;
  {
    std::lock_guard<std::mutex> lock(g_mutex);
    // Writer threads may still create a file or folder while we remove: a few passes apart.
    for (int pass = 0; pass < 4; ++pass) {
      if (pass) std::this_thread::sleep_for(std::chrono::milliseconds(30));
      for (const Claim& c : g_claims) undo(c);
      for (const fs::path& d : g_work_dirs) {
        std::error_code ec;
        fs::remove(d / (".btfc-work-" + pid_text() + ".btf"), ec);
      }
    }
    std::fprintf(stderr, "\nerror: interrupted (%s); temporary files removed, existing outputs kept\n", sig == SIGINT ? "SIGINT" : "SIGTERM");
    std::fflush(stderr);
    _exit(128 + sig);  // 130 / 143, the shell convention
  }
}

}  // namespace

void set_force(bool force) { g_force = force; }
bool force_enabled() { return g_force; }

Status claim_output(const std::string& out_text, const std::vector<std::string>& inputs, const OutputRule& rule) {
  const std::string opt = rule.option + " " + out_text;
  if (out_text.empty()) return invalid_argument(rule.option + ": empty path");
  if (out_text == "-") {
    if (rule.stream) return {};
    return invalid_argument(opt + ": '-' (stdout) is accepted only for streams (bench --csv / --json-out, tilecache --csv); give a path");
  }
  const fs::path out = strip_slashes(out_text);
  const std::string ext = lower(out.extension().string());
  const bool ext_ok = std::find(rule.file_exts.begin(), rule.file_exts.end(), ext) != rule.file_exts.end();
  const bool trailing_slash = out_text.back() == '/';
  if (!ext_ok || (trailing_slash && !rule.dir)) {
    std::vector<std::string> kinds = rule.file_exts;
    if (rule.dir) kinds.push_back("a directory");
    if (!rule.dir || is_file_ext(ext))
      return invalid_argument(opt + ": this command writes " + join(kinds) + (ext.empty() ? "" : ", not " + ext));
  }
  std::error_code ec;
  const fs::path parent = out.parent_path().empty() ? fs::path(".") : out.parent_path();
  if (!fs::is_directory(parent, ec)) return io_error(out_text + ": directory " + parent.string() + " does not exist");
  if (::access(parent.c_str(), W_OK) != 0) return io_error(out_text + ": directory " + parent.string() + " is not writable");
  const bool exists = fs::symlink_status(out, ec).type() != fs::file_type::not_found;
  if (exists) {
    for (const std::string& in : inputs) {
      if (in.empty() || in == "-") continue;
      std::error_code e1;
      if (fs::exists(in, e1) && fs::equivalent(in, out, e1))
        return invalid_argument(opt + ": is the input " + in + " (same file); write the output elsewhere");
      const fs::path ci = fs::weakly_canonical(in, e1), co = fs::weakly_canonical(out, e1);
      if (!e1 && fs::is_directory(co, e1) && inside(co, ci))
        return invalid_argument(opt + ": the directory contains the input " + in + "; write the output elsewhere");
    }
    if (!g_force)
      return invalid_argument(opt + ": " + (fs::is_directory(out, ec) ? "directory" : "file") + " exists (--force replaces it)");
  }
  Claim c{out, {}, exists};
  if (exists) {
    c.aside = parent / (".btfc-old-" + pid_text() + "-" + out.filename().string());
    fs::rename(out, c.aside, ec);
    if (ec) return io_error(out_text + ": cannot move the existing output aside for --force: " + ec.message());
  }
  std::lock_guard<std::mutex> lock(g_mutex);
  g_claims.push_back(c);
  return {};
}

Status require_input(const std::string& path) {
  std::error_code ec;
  if (path.empty() || fs::symlink_status(path, ec).type() == fs::file_type::not_found || !fs::exists(path, ec))
    return io_error(path + ": no such file or directory");
  return {};
}

void register_work_dir(const std::string& dir) {
  std::lock_guard<std::mutex> lock(g_mutex);
  g_work_dirs.push_back(dir);
}

void finish_outputs(bool success) {
  std::lock_guard<std::mutex> lock(g_mutex);
  for (const Claim& c : g_claims) {
    std::error_code ec;
    if (!success) undo(c);
    else if (!c.aside.empty()) fs::remove_all(c.aside, ec);
  }
  g_claims.clear();
}

void install_interrupt_cleanup() {
  if (::pipe(g_pipe) != 0) return;
  bool any = false;
  for (int sig : {SIGINT, SIGTERM}) {
    // A signal the parent set to be ignored (a background job of a script ignores SIGINT) stays ignored.
    struct sigaction old {};
    if (sigaction(sig, nullptr, &old) != 0 || old.sa_handler == SIG_IGN) continue;
    struct sigaction sa {};
    sa.sa_handler = on_signal;
    sigemptyset(&sa.sa_mask);
    sa.sa_flags = SA_RESTART;
    sigaction(sig, &sa, nullptr);
    any = true;
  }
  if (any) std::thread(wait_for_signals).detach();
}

std::string user_paths(const std::string& message) {
  static const std::regex tmp("\\.tmp-(" + std::to_string(::getpid()) + "[A-Za-z0-9._-]*|export)");
  return std::regex_replace(message, tmp, "");
}

}  // namespace btfc::cli
