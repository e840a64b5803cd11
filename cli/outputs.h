// What btfc may write, and what is left when it stops (nothing lost, nothing half-written).
//
// Every command claims its outputs before it reads anything (claim_output):
//  - "-" is stdout, accepted only where a stream makes sense (CSV, JSON), refused elsewhere;
//  - the extension must match what the command writes (compress -o x.png is refused);
//  - an output that is an input (same inode and device, through symlinks), or a directory that
//    contains an input, is refused even with --force;
//  - an existing output (file or directory alike) is refused unless --force; with --force it is
//    moved aside (".btfc-old-PID-NAME" beside it) and deleted only when the command succeeded,
//    restored otherwise: a failed or interrupted run leaves the old output as it was.
// finish_outputs() settles the claims when the command returns. install_interrupt_cleanup()
// starts a thread that waits for SIGINT / SIGTERM: it removes the temporaries the writers make
// beside a claimed output (NAME.tmp-PID*, NAME.tmp-export, .btfc-work-PID.btf), restores
// moved-aside outputs, prints "interrupted" and exits 130 (SIGINT) or 143 (SIGTERM).
#pragma once
#include <string>
#include <vector>

#include "core/status.h"

namespace btfc::cli {

struct OutputRule {
  std::string option;                  // how the user named it, e.g. "-o" or "--csv" (messages)
  std::vector<std::string> file_exts;  // accepted file extensions, lower case with the dot
  bool dir = false;                    // a directory is accepted (a path without a file extension)
  bool stream = false;                 // "-" writes to stdout
};

// Checks `out` against the rule and the inputs; registers it for cleanup. A "-" that the rule
// accepts is returned ok and not registered. --force is the process-wide set_force().
Status claim_output(const std::string& out, const std::vector<std::string>& inputs, const OutputRule& rule);
// The one wording of a missing input: "PATH: no such file or directory" (exit 2).
Status require_input(const std::string& path);
// A directory where temporary working files (.btfc-work-PID.btf) may appear (bench: the temp dir).
void register_work_dir(const std::string& dir);
// Success: delete what --force moved aside. Failure: restore it.
void finish_outputs(bool success);
void set_force(bool force);
bool force_enabled();
// Installs SIGINT / SIGTERM handlers (unless the parent ignored them) and starts the thread
// that cleans up and exits when one arrives.
void install_interrupt_cleanup();
// `message` with this process's temporary suffixes (".tmp-PID...", ".tmp-export") removed, so
// an error names the user's path.
std::string user_paths(const std::string& message);

}  // namespace btfc::cli
