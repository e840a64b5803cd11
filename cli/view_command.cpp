// `btfc view DIR [DIR2]`: serves the web viewer (viewer/, WebGL2) and one or two `btfc export`
// directories on localhost and prints the URL; two directories are shown side by side.
// The HTTP server is Debian's cpp-httplib (libcpp-httplib-dev): static files only, bound to the
// loopback address by default, so the exports are not offered to the network.
#include <CLI/CLI.hpp>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <nlohmann/json.hpp>

#include "cli/commands.h"
#include "cli/outputs.h"
#if BTFC_HAVE_HTTPLIB
#include <httplib.h>
#endif

namespace btfc::cli {
namespace {
namespace fs = std::filesystem;

struct ViewArgs {
  std::vector<std::string> dirs;
  std::string viewer, host = "127.0.0.1";
  int port = 8021;
};

bool is_viewer(const fs::path& d) { return fs::is_regular_file(d / "index.html") && fs::is_regular_file(d / "main.js"); }

// The viewer's files with its npm packages (viewer/install.sh DEST): --viewer, $BTFC_VIEWER_DIR,
// the build tree beside this binary (build/viewer), an installed share/btfc/viewer.
Result<fs::path> find_viewer(const std::string& given) {
  std::vector<fs::path> tried;
  if (!given.empty()) {
    tried.push_back(given);
  } else {
    if (const char* e = std::getenv("BTFC_VIEWER_DIR"); e && *e) tried.push_back(e);
    std::error_code ec;
    const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
    if (!ec) tried.push_back(exe.parent_path() / "viewer"), tried.push_back(exe.parent_path().parent_path() / "share/btfc/viewer");
  }
  std::string names;
  for (const fs::path& d : tried) {
    if (is_viewer(d)) {
      if (!fs::is_regular_file(d / "node_modules/three/build/three.module.js"))
        return invalid_argument(d.string() + ": the viewer's npm packages are not installed (run viewer/install.sh " + d.string() + ")");
      return d;
    }
    names += (names.empty() ? "" : ", ") + d.string();
  }
  return invalid_argument("the web viewer was not found (looked in " + names +
                          "); install it with viewer/install.sh build/viewer, or name it with --viewer DIR");
}

int cmd_view(const Global& g, const ViewArgs& a) {
  if (a.dirs.empty() || a.dirs.size() > 2) return fail(g, invalid_argument("view: one or two export directories"));
  for (const std::string& d : a.dirs) {
    if (Status s = require_input(d); !s.ok()) return fail(g, s);
    // Only the manifest is checked here: a broken export (a missing texture, a bad manifest) is
    // served as it is, and the page says what is wrong with it.
    if (!fs::is_regular_file(fs::path(d) / "manifest.json"))
      return fail(g, invalid_argument(d + ": no manifest.json: not a btfc export directory (make one with btfc export MODEL --to DIR)"));
  }
  auto viewer = find_viewer(a.viewer);
  if (!viewer.ok()) return fail(g, viewer.status());
#if !BTFC_HAVE_HTTPLIB
  return fail(g, unsupported("view: btfc was built without cpp-httplib (apt-get install libcpp-httplib-dev, then rebuild)"));
#else
  httplib::Server svr;
  // A browser keeps idle keep-alive connections open, each holding one of the pool's threads
  // (8 by default): with both panels' ~40 requests, new connections waited for the 5 s
  // keep-alive timeout. More threads and a 1 s timeout keep page loads at file-reading speed.
  svr.new_task_queue = [] { return new httplib::ThreadPool(32); };
  svr.set_keep_alive_timeout(1);
  // JavaScript as application/x-javascript (a JavaScript MIME type browsers accept for modules):
  // httplib brotli-compresses text/javascript for every browser request, which took 2-3 s for
  // three.js's 1.5 MB on each page load; on localhost compression only costs.
  for (auto [ext, type] : {std::pair{"js", "application/x-javascript"}, {"mjs", "application/x-javascript"}, {"json", "application/json"},
                           {"ktx2", "image/ktx2"}, {"frag", "text/plain"}, {"bsvtf", "application/octet-stream"}})
    svr.set_file_extension_and_mimetype_mapping(ext, type);
  // Exports under /a/ and /b/ (the page's ?a= and ?b=), the viewer at the root. Mounts are tried
  // in this order, so an export's files are never shadowed by the viewer's.
  const char* mounts[] = {"/a/", "/b/"};
  for (size_t i = 0; i < a.dirs.size(); ++i)
    if (!svr.set_mount_point(mounts[i], fs::absolute(a.dirs[i]).string()))
      return fail(g, io_error(a.dirs[i] + ": cannot be served"));
  svr.set_mount_point("/", fs::absolute(viewer.value()).string());
  // Missing files are what a user of a broken export needs to see in the terminal too.
  if (!g.quiet)
    svr.set_logger([](const httplib::Request& req, const httplib::Response& res) {
      if (res.status >= 400) std::cerr << res.status << " " << req.method << " " << req.path << "\n";
    });
  const int port = a.port == 0 ? svr.bind_to_any_port(a.host) : (svr.bind_to_port(a.host, a.port) ? a.port : -1);
  if (port <= 0)
    return fail(g, io_error("view: cannot listen on " + a.host + ":" + std::to_string(a.port) + " (in use? --port 0 picks a free port)"));
  std::string url = "http://" + a.host + ":" + std::to_string(port) + "/?a=a/";
  if (a.dirs.size() > 1) url += "&b=b/";
  if (g.json) std::cout << nlohmann::json{{"url", url}, {"viewer", viewer->string()}, {"directories", a.dirs}}.dump() << std::endl;
  else std::cout << "btfc viewer at " << url << "  (serving " << a.dirs[0] << (a.dirs.size() > 1 ? " and " + a.dirs[1] : "")
                 << "; Ctrl-C stops)" << std::endl;
  if (!svr.listen_after_bind()) return fail(g, io_error("view: the server stopped"));
  return 0;
#endif
}

}  // namespace

void add_view_command(CLI::App& app, const Global& g, int& code) {
  static ViewArgs a;
  auto* v = app.add_subcommand("view", "serve the web viewer (WebGL2) for one export directory, or two side by side, on localhost and print its URL");
  v->add_option("dirs", a.dirs, "export directories written by btfc export (one, or two to compare)")->required()->expected(1, 2);
  v->add_option("--port", a.port, "TCP port (0: any free port)")->check(CLI::Range(0, 65535));
  v->add_option("--host", a.host, "address to listen on (the default serves this machine only)");
  v->add_option("--viewer", a.viewer, "viewer directory (viewer/install.sh DIR); default: $BTFC_VIEWER_DIR, then viewer/ beside the binary (the build tree), "
                                "then ../share/btfc/viewer (cmake --install)");
  v->callback([&] { code = cmd_view(g, a); });
}

}  // namespace btfc::cli
