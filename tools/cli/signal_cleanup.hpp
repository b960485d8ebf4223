// What a run leaves behind when SIGINT, SIGTERM or SIGHUP ends it (Ctrl-C,
// `timeout`, a batch system's time limit, mpirun after a rank died): the
// temporary files of its outputs are removed, so that an interrupted run,
// like a failed one, leaves nothing (SIGKILL and the out-of-memory killer
// still can: the next write of the same output removes those).
//
// start_signal_cleanup() runs first thing in main, before any thread exists:
// it blocks the three signals in every thread the process will start and
// waits for them on a thread of its own, where removing files needs no
// async-signal care. On a signal that thread removes the temporaries of the
// outputs registered so far, then ends the process by the same signal (the
// shell sees it killed by SIGINT, as without this). Child processes unblock
// every signal before exec (tools/isolated/isolated_worker.cpp).
#pragma once

#include <string>

namespace ivol::cli {

void start_signal_cleanup();

// After a temporary file for `output` may exist: files ".<name>.tmp-*" next
// to it, made since this process started (another run's may be older), are
// removed on a signal. libformat's writers and StagedFile name their
// temporaries so. Several outputs may be registered.
void remove_temporaries_on_signal(const std::string& output);

}  // namespace ivol::cli
