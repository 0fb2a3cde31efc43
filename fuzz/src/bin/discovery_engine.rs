//! The discovery engine (`discovery::Engine::handle_datagram`, timers, local endpoints) fed
//! scripts of datagrams, in clear and sealed with the fixture key: see `ndds_fuzz::discovery`
//! for the script format.

fn main() {
    ndds_fuzz::main(ndds_fuzz::discovery::run);
}
