#pragma once
// Messaging shared by the lfrecon daemons and the client: every message is one
// lfrecon.v1.Envelope (proto/lfrecon_service.proto) in one ZeroMQ frame.
//  * Version: an envelope whose `version` is not kProtocolVersion is refused
//    with ERROR_VERSION.
//  * Size: a payload larger than the limit (max_message_bytes) is refused with
//    ERROR_TOO_LARGE without being parsed; ZeroMQ itself drops (and
//    disconnects) anything above TransportLimit(), so no allocation is ever
//    unbounded. Every socket made here has both limits.
//  * Anything that does not parse gets ERROR_MALFORMED. A daemon never dies
//    of a message.
//  * Security: CURVE with an allow-list and roles on network endpoints, ipc://
//    only in private folders (auth.h); a message its sender's role may not
//    send gets ERROR_FORBIDDEN.
// Requests are REQ (client, "lazy pirate": on timeout the socket is rebuilt
// and the request re-sent) -> ROUTER (daemon).
#include <chrono>
#include <memory>
#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>
#include <zmq.hpp>

#include "common/auth.h"
#include "lfrecon_service.pb.h"

namespace lfrecon::svc {

namespace pb = ::lfrecon::v1;

constexpr std::uint32_t kProtocolVersion = 1;
constexpr std::int64_t kDefaultMaxMessageBytes = 128ll << 20;

// ZeroMQ's own limit for a socket whose messages may be `max_message_bytes`:
// room for the application check to see (and answer) oversized messages.
inline std::int64_t TransportLimit(std::int64_t max_message_bytes) { return 2 * max_message_bytes + (1 << 20); }

// Endpoints of the stack (flags override; loopback by default).
constexpr const char* kDefaultIngestEndpoint = "tcp://127.0.0.1:5550";
constexpr const char* kDefaultAggregateEndpoint = "tcp://127.0.0.1:5551";
// The value of environment variable `name` if set, else `fallback`.
std::string EndpointFromEnv(const char* name, const std::string& fallback);

// An error reply received from a daemon, or a transport failure (code ERROR_UNKNOWN, "no reply ...").
class ServiceError : public std::runtime_error {
 public:
  ServiceError(pb::ErrorCode code, const std::string& message) : std::runtime_error(message), code_(code) {}
  pb::ErrorCode code() const { return code_; }

 private:
  pb::ErrorCode code_;
};

pb::Envelope NewEnvelope(const std::string& job_id = "");
pb::Envelope ErrorEnvelope(pb::ErrorCode code, const std::string& message, const std::string& job_id = "");
std::string Serialize(const pb::Envelope& env);
// Size check, parse, version check. On failure returns false and fills *error.
bool DecodeEnvelope(const void* data, std::size_t size, std::int64_t max_message_bytes, pb::Envelope* env,
                    pb::ErrorReply* error);
// Which body an envelope carries, for logs ("status", "task_result", ...).
std::string BodyName(const pb::Envelope& env);

// Linger 0 and the transport size limit.
void ConfigureSocket(zmq::socket_t& socket, std::int64_t max_message_bytes);
// Bounds the socket's blocking sends by `timeout`: a REQ or DEALER socket's send blocks while it
// has no peer to send to (a server that refused the CURVE handshake leaves it none).
void SetSendTimeout(zmq::socket_t& socket, std::chrono::milliseconds timeout);

// A REQ client with timeouts and reconnect ("lazy pirate").
class RequestClient {
 public:
  // Throws OptionError when the endpoint needs keys that `security` lacks (CheckClientEndpoint).
  RequestClient(zmq::context_t& context, std::string endpoint,
                std::int64_t max_message_bytes = kDefaultMaxMessageBytes, ClientSecurity security = {});
  // Sends `request` and waits up to `timeout`; retries (rebuilding the socket)
  // up to `attempts` times. Returns nullopt when nothing answered. A reply that
  // is malformed, oversized or of another version becomes an ErrorReply envelope.
  std::optional<pb::Envelope> Request(const pb::Envelope& request, std::chrono::milliseconds timeout,
                                      int attempts = 1);
  // Request() that throws ServiceError on no reply or on an ErrorReply.
  pb::Envelope Call(const pb::Envelope& request, std::chrono::milliseconds timeout, int attempts = 1);
  // Raw bytes (tests: malformed input); same reply handling.
  std::optional<pb::Envelope> RequestRaw(const std::string& bytes, std::chrono::milliseconds timeout);
  const std::string& endpoint() const { return endpoint_; }

 private:
  void Reset();
  zmq::context_t& context_;
  std::string endpoint_;
  std::int64_t max_message_bytes_;
  ClientSecurity security_;
  std::optional<zmq::socket_t> socket_;
};

// The daemon side: a ROUTER socket bound to an endpoint.
class RouterServer {
 public:
  struct Incoming {
    std::vector<zmq::message_t> route;  // identity frames (+ empty delimiter), echoed in the reply
    bool ok = false;                    // false: `error` says why (malformed, too large, version)
    pb::Envelope envelope;
    pb::ErrorReply error;
    std::size_t bytes = 0;
    Role role = Role::kNone;  // the sender's (kLocal on a socket without CURVE)
    std::string peer;         // its key's name in the allow-list
    std::string peer_key;     // its CURVE public key (Z85): who it is; empty without CURVE
  };
  // With CURVE (security.key) it starts the context's ZAP handler before it
  // binds: the context must have no other. Throws OptionError when the
  // endpoint is not allowed under `security` (CheckServerEndpoint).
  RouterServer(zmq::context_t& context, const std::string& endpoint,
               std::int64_t max_message_bytes = kDefaultMaxMessageBytes, const ServerSecurity& security = {});
  // Waits up to `timeout` for one request. One that its sender's role may not
  // send comes back with ok false and ERROR_FORBIDDEN.
  std::optional<Incoming> Receive(std::chrono::milliseconds timeout);
  void Reply(Incoming& in, const pb::Envelope& reply);
  zmq::socket_t& socket() { return socket_; }

 private:
  std::int64_t max_message_bytes_;
  bool curve_ = false;
  std::unique_ptr<ZapHandler> zap_;  // before socket_: destroyed after it
  zmq::socket_t socket_;
};

// Installs SIGINT/SIGTERM handlers that set a flag; StopRequested() reads it.
void InstallStopHandlers();
bool StopRequested();

}  // namespace lfrecon::svc
