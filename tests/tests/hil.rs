//! Hardware-in-the-loop tests on a real SocketCAN interface (vcan0 by default).
//! They are `#[ignore]`d so that `cargo test --workspace` on a machine without CAN reports
//! them as ignored instead of failing; `scripts/hil.sh` runs them (`--ignored`) where vcan0
//! is up, booting a CAN-capable guest when this kernel has none.

use std::thread;
use std::time::{Duration, Instant};

use socketcan::{CanFrame, CanSocket, EmbeddedFrame, Socket, StandardId};
use vge_bridge::emulator::{JointControllerEmulator, serve};
use vge_bridge::protocol::{FingerId, JointCommand, JointState, NUM_FINGERS};
use vge_bridge::socketcan_io::{standard_id_and_data, to_can_frame};
use vge_tests::hil_iface;

const READ_TIMEOUT: Duration = Duration::from_secs(2);

fn open(iface: &str) -> CanSocket {
    CanSocket::open(iface).unwrap_or_else(|e| {
        panic!("cannot open CAN interface {iface}: {e}. HIL tests need it up: run scripts/hil.sh")
    })
}

#[test]
#[ignore = "needs vcan0: run scripts/hil.sh"]
fn two_sockets_exchange_frames_on_vcan() {
    let iface = hil_iface();
    let a = open(&iface);
    let b = open(&iface);
    b.set_read_timeout(READ_TIMEOUT).expect("read timeout");

    for i in 0..100u8 {
        let id = StandardId::new(0x300 + u16::from(i)).expect("11-bit id");
        let data = [i, i.wrapping_mul(3), 0xa5, 0x5a, 0, 1, 2, i];
        let sent = CanFrame::new(id, &data[..usize::from(i % 9)]).expect("classic frame");
        a.write_frame(&sent).expect("write");
        let got = b.read_frame().expect("the other socket receives the frame");
        assert_eq!(got.id(), sent.id());
        assert_eq!(got.data(), sent.data());
    }
}

#[test]
#[ignore = "needs vcan0: run scripts/hil.sh"]
fn joint_controller_emulator_answers_commands_over_vcan() {
    let iface = hil_iface();
    // Filter-free sockets see every frame on the bus, including other tests' traffic: use a
    // dedicated finger-range check and sequence numbers to pick out our replies.
    let client = open(&iface);
    client.set_read_timeout(READ_TIMEOUT).expect("read timeout");

    let rounds: u8 = 20;
    let expected = u64::from(rounds) * u64::from(NUM_FINGERS);
    let server_iface = iface.clone();
    let server = thread::spawn(move || {
        let mut emulator = JointControllerEmulator::new(0.5);
        serve(&server_iface, &mut emulator, expected, READ_TIMEOUT)
    });
    // The server must be listening before the first command: CAN does not queue for sockets
    // opened later. Give it a moment, then check it answered every command.
    thread::sleep(Duration::from_millis(200));

    let target_rad = [0.3, 0.8, -0.4];
    let mut last = [None::<JointState>; NUM_FINGERS as usize];
    let start = Instant::now();
    for seq in 0..rounds {
        for f in 0..NUM_FINGERS {
            let cmd = JointCommand {
                finger: FingerId::new(f).expect("finger"),
                q_target_rad: target_rad,
                enable: true,
                seq,
            };
            client.write_frame(&to_can_frame(&cmd.encode().expect("encode")).expect("frame")).expect("write");
            let state = loop {
                let frame = client.read_frame().expect("a joint state reply before the timeout");
                let (id, data) = standard_id_and_data(&frame).expect("data frame");
                if let Ok(state) = JointState::decode(id, data) {
                    break state;
                }
            };
            assert_eq!(state.finger.index(), f);
            assert_eq!(state.seq, seq, "reply echoes the command's sequence number");
            last[usize::from(f)] = Some(state);
        }
    }
    let elapsed = start.elapsed();
    let stats = server.join().expect("server thread").expect("server ran");
    assert_eq!(stats.commands, expected);

    // After 20 halvings of the error the joints sit on the target (to the wire's resolution).
    for state in last.iter().flatten() {
        for (q, t) in state.q_rad.iter().zip(target_rad) {
            assert!((q - t).abs() < 2e-4, "finger {} joint at {q} rad, target {t}", state.finger.index());
        }
        assert_eq!(state.status & 1, 1, "enabled");
    }
    eprintln!(
        "hil: {expected} command/state round trips on {iface} in {:.1} ms ({:.0} us each)",
        elapsed.as_secs_f64() * 1e3,
        elapsed.as_secs_f64() * 1e6 / expected as f64
    );
}
