//! A participant's data plane (`participant::ParticipantCore::handle_datagram`, timers,
//! writes, credit, matches) fed scripts of data and feedback from a matched peer, in clear
//! and sealed: see `ndds_fuzz::participant` for the script format.

fn main() {
    ndds_fuzz::main(ndds_fuzz::participant::run);
}
