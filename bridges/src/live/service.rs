//! ROS 2 services over DDS, server side, and the `simulation_interfaces` services of the
//! bridge: get/set the simulation state (pause, resume, stop, quit), step, reset.
//!
//! A ROS 2 service `/x/y` of type `pkg/srv/T` is two DDS topics: requests on `rq/x/yRequest`
//! (type `pkg::srv::dds_::T_Request_`) and replies on `rr/x/yReply` (`T_Response_`). The
//! reply names its request in one of the two ways the rmw layers use, and the server answers
//! each request the way it came:
//! - rmw_cyclonedds: a 16-byte header at the start of the payload, `uint64 client_guid,
//!   int64 sequence_number`, echoed at the start of the reply;
//! - rmw_fastrtps (and RTPS-level RPC): no header; the request carries a related sample
//!   identity (inline QoS) and the reply carries the request's sample identity (writer GUID +
//!   sequence number) as its related sample identity.

use super::dds::{Node, RawCdr, RawReader, RawWriter};
use rustdds::policy::{Durability, History, Reliability};
use rustdds::{QosPolicyBuilder, SampleIdentity, WriteOptionsBuilder};
use twin_core::error::{Error, Result};
use twin_core::log::cdr::{CdrError, CdrReader, CdrWriter};

/// The request a reply answers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RequestId {
    /// rmw_cyclonedds: the payload header.
    Header {
        /// The client's id.
        client_guid: u64,
        /// The client's request counter.
        sequence_number: i64,
    },
    /// rmw_fastrtps: the request sample's identity.
    Sample(SampleIdentity),
}

/// One request: who asked, and its fields as CDR (encapsulation header first, rmw header
/// removed), ready for a [`CdrReader`].
#[derive(Debug, Clone)]
pub struct Request {
    /// Who asked.
    pub id: RequestId,
    /// The request's fields.
    pub cdr: Vec<u8>,
}

impl Request {
    /// A reader of the request's fields.
    ///
    /// # Errors
    /// A [`CdrError`] when the payload has no valid header.
    pub fn reader(&self) -> std::result::Result<CdrReader<'_>, CdrError> {
        CdrReader::new(&self.cdr)
    }
}

/// The server side of one service.
pub struct ServiceServer {
    name: String,
    requests: RawReader,
    replies: RawWriter,
}

/// DDS topic and type names of service `name` (`/twin/step_simulation`) of type `srv_type`
/// (`simulation_interfaces/srv/StepSimulation`): (request topic, request type, reply topic,
/// reply type).
pub fn dds_names(name: &str, srv_type: &str) -> (String, String, String, String) {
    let base = name.trim_start_matches('/');
    let ty = super::dds::dds_type(srv_type);
    let ty = ty.trim_end_matches('_');
    (format!("rq/{base}Request"), format!("{ty}_Request_"), format!("rr/{base}Reply"), format!("{ty}_Response_"))
}

impl ServiceServer {
    /// Offers service `name` of type `srv_type` on `node` with the rmw default service QoS
    /// (reliable, volatile, keep last 10).
    ///
    /// # Errors
    /// [`Error::Live`] from rustdds.
    pub fn new(node: &Node, name: &str, srv_type: &str) -> Result<ServiceServer> {
        let (rq, rq_type, rr, rr_type) = dds_names(name, srv_type);
        let policies = QosPolicyBuilder::new()
            .reliability(Reliability::Reliable { max_blocking_time: rustdds::Duration::ZERO })
            .durability(Durability::Volatile)
            .history(History::KeepLast { depth: 10 })
            .build();
        let replies = node.dds_writer(&rr, &rr_type, policies, name)?;
        let requests = node.dds_reader(&rq, &rq_type, 10, name)?;
        Ok(ServiceServer { name: name.to_string(), requests, replies })
    }

    /// The service's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The request reader (to register with a poller).
    pub fn requests_mut(&mut self) -> &mut RawReader {
        &mut self.requests
    }

    /// The next request, if one is waiting. A request too short for its rmw header is
    /// dropped (returned as `Err` with a sentence saying why).
    pub fn take(&mut self) -> Option<std::result::Result<Request, String>> {
        let sample = match self.requests.take_next_sample() {
            Ok(Some(s)) => s,
            _ => return None,
        };
        let identity = sample.sample_info().sample_identity();
        let rtps = sample.sample_info().related_sample_identity().is_some();
        let RawCdr(bytes) = sample.into_value();
        Some(split_request(bytes, rtps.then_some(identity)).map_err(|e| format!("{}: {e}", self.name)))
    }

    /// Replies to `id` with the response fields `encode` writes.
    ///
    /// # Errors
    /// [`Error::Live`] when the reply can't be written.
    pub fn reply(&self, id: &RequestId, encode: impl FnOnce(&mut CdrWriter)) -> Result<()> {
        let mut w = CdrWriter::new();
        let written = match id {
            RequestId::Header { client_guid, sequence_number } => {
                w.u64(*client_guid);
                w.i64(*sequence_number);
                encode(&mut w);
                self.replies.write(RawCdr(w.bytes().to_vec()), None).map(|_| ())
            }
            RequestId::Sample(identity) => {
                encode(&mut w);
                let options = WriteOptionsBuilder::new().related_sample_identity(*identity).build();
                self.replies.write_with_options(RawCdr(w.bytes().to_vec()), options).map(|_| ())
            }
        };
        written.map_err(|e| Error::Live { message: format!("replying on {}: {e}", self.name) })
    }
}

/// Splits a request sample into its id and fields: `identity` is the sample's identity when
/// it came the rmw_fastrtps way (no payload header).
///
/// # Errors
/// A sentence when the payload is shorter than the rmw_cyclonedds header.
pub fn split_request(bytes: Vec<u8>, identity: Option<SampleIdentity>) -> std::result::Result<Request, String> {
    if let Some(identity) = identity {
        return Ok(Request { id: RequestId::Sample(identity), cdr: bytes });
    }
    let mut r = CdrReader::new(&bytes).map_err(|e| e.message)?;
    let client_guid = r.u64().map_err(|_| "request shorter than its 16-byte rmw header".to_string())?;
    let sequence_number = r.i64().map_err(|_| "request shorter than its 16-byte rmw header".to_string())?;
    // The header is 16 bytes, a multiple of every alignment: the fields keep theirs.
    let mut cdr = Vec::with_capacity(bytes.len() - 16);
    cdr.extend_from_slice(&bytes[..4]);
    cdr.extend_from_slice(&bytes[20..]);
    Ok(Request { id: RequestId::Header { client_guid, sequence_number }, cdr })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn service_names_follow_ros2_dds_naming() {
        let (rq, rq_t, rr, rr_t) = dds_names("/twin/step_simulation", "simulation_interfaces/srv/StepSimulation");
        assert_eq!(rq, "rq/twin/step_simulationRequest");
        assert_eq!(rq_t, "simulation_interfaces::srv::dds_::StepSimulation_Request_");
        assert_eq!(rr, "rr/twin/step_simulationReply");
        assert_eq!(rr_t, "simulation_interfaces::srv::dds_::StepSimulation_Response_");
    }

    #[test]
    fn the_cyclone_header_is_split_off_and_fields_keep_their_alignment() {
        let mut w = CdrWriter::new();
        w.u64(0x1122_3344_5566_7788);
        w.i64(42);
        w.u64(7); // StepSimulation_Request.steps
        let req = split_request(w.bytes().to_vec(), None).unwrap();
        assert_eq!(req.id, RequestId::Header { client_guid: 0x1122_3344_5566_7788, sequence_number: 42 });
        assert_eq!(req.reader().unwrap().u64().unwrap(), 7);
        let short = {
            let mut w = CdrWriter::new();
            w.u32(1);
            w.bytes().to_vec()
        };
        assert!(split_request(short, None).unwrap_err().contains("16-byte rmw header"));
    }

    #[test]
    fn a_request_with_a_sample_identity_has_no_payload_header() {
        let mut w = CdrWriter::new();
        w.u64(7);
        let identity = SampleIdentity {
            writer_guid: rustdds::GUID::GUID_UNKNOWN,
            sequence_number: rustdds::SequenceNumber::from(3),
        };
        let req = split_request(w.bytes().to_vec(), Some(identity)).unwrap();
        assert_eq!(req.id, RequestId::Sample(identity));
        assert_eq!(req.reader().unwrap().u64().unwrap(), 7);
    }
}
