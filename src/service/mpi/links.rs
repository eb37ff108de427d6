//! The MPI implementations of [`MasterLink`] and [`WorkerLink`].
//!
//! Rank 0 receives with matched probes (`MPI_Improbe` + `MPI_Mrecv`, MPI 4.0 §3.8.2–3):
//! messages have variable sizes (compressed chunks), so each is received into a buffer of
//! exactly its size, which then moves to the writer thread without a copy. Probing is
//! nonblocking and the master sleeps briefly between empty probes, so waiting costs no
//! core (Open MPI's blocking calls busy-poll, which would steal a core from compute
//! threads on a small node). Memory at rank 0 is bounded by the writer queue: while it is
//! full the master stops receiving and the workers' sends block.

use std::time::{Duration, Instant};

use mpi::point_to_point::{Destination, Source};
use mpi::topology::{Communicator, SimpleCommunicator};
use mpi::traits::Equivalence;

use super::protocol as p;
use crate::ffz::EncodedChunk;
use crate::service::link::{MasterLink, ToMaster, WorkerLink};
use crate::service::{ServiceError, WorkerStats};

pub(crate) struct MpiMasterLink<'a> {
    pub(crate) world: &'a SimpleCommunicator,
}

impl MpiMasterLink<'_> {
    fn receive(&self) -> Result<Option<(usize, ToMaster)>, ServiceError> {
        let Some((msg, status)) = self.world.any_process().immediate_matched_probe() else {
            return Ok(None);
        };
        let rank = status.source_rank();
        let worker = (rank - 1) as usize;
        let tag = status.tag();
        if tag == p::ASSIGN || tag == p::GATHER_ROW {
            return Err(ServiceError::Transport(format!(
                "unexpected message tag {tag} from rank {rank}"
            )));
        }
        let count = status.count(u8::equivalent_datatype()) as usize;
        let mut buf = vec![0u8; count];
        msg.matched_receive_into(&mut buf[..]);
        Ok(Some((
            worker,
            match tag {
                p::REQUEST => ToMaster::Request { worker },
                p::CHUNK => ToMaster::Chunk {
                    chunk: p::decode_chunk_message(buf, rank)?,
                },
                p::PIECE => ToMaster::Piece {
                    chunk: p::decode_chunk_message(buf, rank)?,
                },
                p::HALF_DONE => ToMaster::HalfRowsDone {
                    worker,
                    rows: p::decode_rows(&buf, rank)?,
                },
                p::FAILED => {
                    let (row, message) = p::decode_failed(&buf, rank)?;
                    ToMaster::Failed { rank, row, message }
                }
                p::DONE => ToMaster::Done {
                    stats: p::decode_done(&buf, rank)?,
                },
                p::SETUP => ToMaster::Failed {
                    rank,
                    row: None,
                    message: String::from_utf8_lossy(&buf).into_owned(),
                },
                p::ALIVE => ToMaster::Alive,
                _ => {
                    return Err(ServiceError::Transport(format!(
                        "unknown message tag {tag} from rank {rank}"
                    )))
                }
            },
        )))
    }
}

impl MasterLink for MpiMasterLink<'_> {
    fn workers(&self) -> usize {
        (self.world.size() - 1) as usize
    }

    fn poll(&mut self, timeout: Duration) -> Result<Option<(usize, ToMaster)>, ServiceError> {
        let start = Instant::now();
        let mut nap = Duration::from_micros(20);
        loop {
            if let Some(m) = self.receive()? {
                return Ok(Some(m));
            }
            if start.elapsed() >= timeout {
                return Ok(None);
            }
            std::thread::sleep(nap);
            nap = (nap * 2).min(Duration::from_millis(1));
        }
    }

    fn rank_of(&self, worker: usize) -> i32 {
        worker as i32 + 1
    }

    fn assign(&mut self, worker: usize, rows: Vec<u32>) -> Result<(), ServiceError> {
        let msg = p::encode_assign(&rows);
        self.world
            .process_at_rank(worker as i32 + 1)
            .send_with_tag(&msg[..], p::ASSIGN);
        Ok(())
    }
}

pub(crate) struct MpiWorkerLink<'a> {
    pub(crate) world: &'a SimpleCommunicator,
}

impl WorkerLink for MpiWorkerLink<'_> {
    fn request(&mut self) -> Result<(), ServiceError> {
        let me = [self.world.rank() as u32];
        self.world
            .process_at_rank(0)
            .send_with_tag(&me[..], p::REQUEST);
        Ok(())
    }

    fn try_assignment(&mut self) -> Result<Option<Vec<u32>>, ServiceError> {
        let Some((msg, status)) = self
            .world
            .process_at_rank(0)
            .immediate_matched_probe_with_tag(p::ASSIGN)
        else {
            return Ok(None);
        };
        let count = status.count(u32::equivalent_datatype()) as usize;
        let mut buf = vec![0u32; count];
        msg.matched_receive_into(&mut buf[..]);
        p::decode_assign(&buf).map(Some)
    }

    fn send_chunk(&mut self, chunk: EncodedChunk) -> Result<(), ServiceError> {
        let msg = p::encode_chunk_message(chunk);
        self.world
            .process_at_rank(0)
            .send_with_tag(&msg[..], p::CHUNK);
        Ok(())
    }

    fn send_piece(&mut self, piece: EncodedChunk) -> Result<(), ServiceError> {
        let msg = p::encode_chunk_message(piece);
        self.world
            .process_at_rank(0)
            .send_with_tag(&msg[..], p::PIECE);
        Ok(())
    }

    fn half_rows_done(&mut self, rows: Vec<u32>) -> Result<(), ServiceError> {
        let msg = p::encode_rows(&rows);
        self.world
            .process_at_rank(0)
            .send_with_tag(&msg[..], p::HALF_DONE);
        Ok(())
    }

    fn failed(&mut self, row: Option<u32>, message: &str) -> Result<(), ServiceError> {
        let msg = p::encode_failed(row, message);
        self.world
            .process_at_rank(0)
            .send_with_tag(&msg[..], p::FAILED);
        Ok(())
    }

    fn done(&mut self, stats: WorkerStats) -> Result<(), ServiceError> {
        let msg = p::encode_done(&stats);
        self.world
            .process_at_rank(0)
            .send_with_tag(&msg[..], p::DONE);
        Ok(())
    }

    fn alive(&mut self) -> Result<(), ServiceError> {
        let nothing: [u8; 0] = [];
        self.world
            .process_at_rank(0)
            .send_with_tag(&nothing[..], p::ALIVE);
        Ok(())
    }
}
