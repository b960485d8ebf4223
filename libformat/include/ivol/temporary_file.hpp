// Temporary files next to an output. Every writer of ivol writes its output
// under a temporary name in the output's directory, ".NAME.tmp-XXXXXX", and
// renames it into place when complete. While it writes, it holds a write
// lock on the file (an open-file-description lock, fcntl F_OFD_SETLK, which
// leaves flock(2) free for libraries such as HDF5 that lock the file they
// write); the kernel drops the lock when the process ends, however it ends. A writer killed outright (SIGKILL, the OOM
// killer) cannot remove its temporary file, so the next writer of the same output removes every such file that nobody
// holds locked.
#pragma once

#include <cstddef>
#include <string>

namespace ivol {

// Creates and locks a new temporary file for `final_path` (mode 0644) and
// returns its descriptor; `temp_path` receives its name. The file is locked
// before it has a name where supported (O_TMPFILE), so a concurrent
// remove_abandoned_temporaries never sees it unlocked. Throws ivol::Error
// naming final_path on failure. Closing the descriptor releases the lock:
// rename the file into place before closing it.
int create_locked_temporary(const std::string& final_path, std::string& temp_path);

// Renames a finished (and flushed) temporary file to `final_path`, replacing
// any file there atomically, and makes the rename durable by flushing the
// directory. Throws ivol::Error naming final_path when the rename fails.
void rename_into_place(const std::string& temp_path, const std::string& final_path);

// From now on, rename_into_place never replaces a file at `final_path`: the
// rename fails if one appeared there, atomically (renameat2 RENAME_NOREPLACE,
// or link + unlink where the file system lacks it). For callers that checked
// that `final_path` does not exist and were not allowed to replace it (the
// command line without -f): the check alone would race with other writers.
// Process-wide, as the files a process may not replace are.
void refuse_to_replace(const std::string& final_path);

// Removes the temporary files of `final_path` that no live writer holds.
// Returns how many it removed. Never touches final_path itself, nor files
// it cannot open.
std::size_t remove_abandoned_temporaries(const std::string& final_path);

}  // namespace ivol
