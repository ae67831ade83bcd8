#pragma once
// The client side of a client-pushed stream (proto/README.md "Streams"): a
// DEALER socket to lfrecon-ingest that opens the job, pushes frames with
// credit-based flow control (the ZeroMQ guide's file-transfer pattern: at most
// `credits` frames unanswered; each answer, a StreamCredit or an error, returns
// one credit) and ends the stream. Its memory and the daemon's are bounded by
// the credits whatever the client's speed. Used by `lfrecon stream` and the tests.
#include <chrono>
#include <cstdint>
#include <optional>
#include <string>
#include <zmq.hpp>

#include "common/messaging.h"

namespace lfrecon::svc {

class StreamClient {
 public:
  // Throws OptionError when the endpoint needs keys that `security` lacks.
  StreamClient(zmq::context_t& context, const std::string& endpoint,
               std::int64_t max_message_bytes = kDefaultMaxMessageBytes, const ClientSecurity& security = {});
  // Opens the job; throws ServiceError on an error reply or no reply within `timeout`.
  pb::StreamOpened Open(const pb::StreamOpen& open, std::chrono::milliseconds timeout);
  // Sends one frame, first waiting (up to `timeout` for each answer) until a
  // credit is free. Throws ServiceError for an error answer (its credit is
  // back) or when no answer comes.
  void Push(const pb::Frame& frame, std::chrono::milliseconds timeout);
  // Sends the end of the stream and waits for every answer, then StreamEnded.
  pb::StreamEnded End(std::uint32_t num_frames, std::chrono::milliseconds timeout);

  const std::string& job_id() const { return job_; }
  int credits() const { return credits_; }
  int in_flight() const { return in_flight_; }          // frames sent and not answered
  int max_in_flight() const { return max_in_flight_; }  // the most there ever were
  int repeated() const { return repeated_; }            // frames ingest answered as repeats
  int stored() const { return stored_; }                // frames_stored of the last credit
  int max_in_flight_ingest() const { return max_in_flight_ingest_; }  // as the ingest daemon counted them

  // Tests: send an envelope (this job's id set) without looking at the credits, and take one answer.
  void SendUnchecked(pb::Envelope env, std::chrono::milliseconds timeout = std::chrono::milliseconds(10000));
  std::optional<pb::Envelope> Receive(std::chrono::milliseconds timeout);

 private:
  // Throws ServiceError when the message cannot be handed to the socket within `timeout`.
  void Send(const pb::Envelope& env, std::chrono::milliseconds timeout);
  // One answer to a frame: a credit back; throws ServiceError for an error answer.
  void Take(const pb::Envelope& env);
  pb::Envelope ReceiveOrThrow(std::chrono::milliseconds timeout);

  std::string endpoint_;
  std::int64_t max_message_bytes_;
  zmq::socket_t socket_;
  std::string job_;
  int credits_ = 0, in_flight_ = 0, max_in_flight_ = 0, repeated_ = 0, stored_ = 0, max_in_flight_ingest_ = 0;
};

}  // namespace lfrecon::svc
