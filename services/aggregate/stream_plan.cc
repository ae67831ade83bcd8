// lfrecon-aggregate, an open stream's growing plan. A client-pushed stream
// that gives V is a job from its StreamOpen on (ingest tells the aggregator,
// and a restarted aggregator finds it in the store): its geometry is the
// frames stored so far (0..n-1), and the plan is computed again on that prefix
// as frames arrive. The views it settles (ReconstructionPlan::SettledFrames:
// their entries are those of the whole stream's plan) are leased and fused
// while the stream is open; the others after its end, when the manifest's plan
// (every camera) replaces the prefix's. A stream without V waits for its end
// (V is estimated from every camera).
#include "aggregator_job.h"

#include <spdlog/spdlog.h>

#include "util/error.h"

namespace lfrecon::svc {

void Aggregator::GrowStream(Job& job) {
  if (!job.active || !job.geo.open) return;
  const int before = job.n;
  try {
    if (store_.Exists(job.id) && store_.ReadText(job.id, "ingest.done")) {
      // Ended: ingest wrote the manifest (every camera; V as the stream gave it) before telling us.
      JobGeometry whole = LoadJobGeometry(store_, job.id);
      if (static_cast<int>(whole.views.size()) < before)
        throw InputError("manifest.pb", "views", std::to_string(whole.views.size()) + " views, but " +
                                                    std::to_string(before) + " frames were stored");
      job.SetGeometry(std::move(whole));
      spdlog::info("aggregate: job {}: stream ended with {} frames, {} views planned", job.id, job.n, job.num_fused);
    } else if (auto status = store_.ReadText(job.id, "status.pb")) {
      // Ingest failed the stream (a gap at its end, its client gone, ingest restarted): the job ends with its reason.
      pb::JobStatus s;
      const std::string why = s.ParseFromString(*status) ? s.message() : "the stream failed at ingest";
      EndJob(job, pb::STATE_FAILED, why);
      return;
    } else if (store_.HasFrame(job.id, before)) {
      JobGeometry grown = job.geo;
      GrowStreamGeometry(store_, &grown, true);  // no plan per frame while nothing settles (nothing is leased)
      job.SetGeometry(std::move(grown));
    } else {
      return;
    }
  } catch (const std::exception& e) {
    EndJob(job, pb::STATE_FAILED, std::string("stream: ") + e.what());
    return;
  }
  for (int k = before; k < job.n; ++k)
    if (!job.frame_ok[k] && store_.HasFrame(job.id, k)) job.frame_ok[k] = 1, ++job.frames_spooled;
  job.last_ingest = Clock::now();
}

}  // namespace lfrecon::svc
