// libFuzzer target: the Envelope parser and the role check every daemon
// applies to a received message (DecodeEnvelope, RoleMaySend), then what a
// daemon does with an accepted one before dispatching on its body: its name
// for the logs, the job id check, and the re-serialized reply path.
#include <spdlog/spdlog.h>

#include "common/auth.h"
#include "common/messaging.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace lfrecon::svc;
  static const bool quiet = [] {
    spdlog::set_level(spdlog::level::off);
    return true;
  }();
  (void)quiet;
  pb::Envelope env;
  pb::ErrorReply error;
  // A small limit too, so that the size check is exercised.
  for (std::int64_t limit : {kDefaultMaxMessageBytes, std::int64_t(256)}) {
    env.Clear();
    error.Clear();
    if (!DecodeEnvelope(data, size, limit, &env, &error)) {
      if (error.code() == pb::ERROR_UNKNOWN || error.message().empty()) __builtin_trap();  // every refusal says why
      Serialize(ErrorEnvelope(error.code(), error.message()));
      continue;
    }
    const std::string body = BodyName(env);
    if (body.empty()) __builtin_trap();
    for (Role r : {Role::kNone, Role::kClient, Role::kWorker, Role::kIngest, Role::kServer, Role::kLocal}) {
      const bool may = RoleMaySend(r, env.body_case());
      if (r == Role::kLocal && !may) __builtin_trap();
      if (r == Role::kNone && may) __builtin_trap();
    }
    (void)ErrorEnvelope(pb::ERROR_BAD_REQUEST, "does not serve '" + body + "'", env.job_id());
    // A decoded envelope re-serializes and decodes to the same message.
    const std::string again = Serialize(env);
    pb::Envelope back;
    pb::ErrorReply e2;
    if (static_cast<std::int64_t>(again.size()) <= limit &&
        (!DecodeEnvelope(again.data(), again.size(), limit, &back, &e2) || back.body_case() != env.body_case()))
      __builtin_trap();
  }
  return 0;
}
