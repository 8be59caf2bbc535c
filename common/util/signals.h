#pragma once
// SIGTERM / SIGINT handling shared by every service: the handler only sets a flag;
// the service's loop sees it, shuts down cleanly and exits 0.
#include <atomic>

namespace cnc::util {

void install_stop_handlers();
bool stop_requested();
int stop_signal();  // the signal that asked for the stop, 0 if none
void request_stop();  // for tests and for a service that decides to end itself
// For batch tools that run through a file with no loop that polls stop_requested():
// SIGTERM and SIGINT end the process at once again (their default action).
void end_at_once_on_stop_signals();

}  // namespace cnc::util
