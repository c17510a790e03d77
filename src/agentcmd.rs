//! `iwsim agent …`: agents built on the agent SDK.

use std::process::ExitCode;

use agent_sdk::{Agent, Wait};
use ipc_types::{ActionBlock, REG_HAS_POSE, RobotRegistration};

use crate::cli::WheelchairArgs;

/// `iwsim agent wheelchair`: registers robots and drives them with constant powers.
pub fn wheelchair(args: &WheelchairArgs) -> anyhow::Result<ExitCode> {
    let timeout = std::time::Duration::from_secs_f64(args.connect_timeout.max(0.0));
    let mut agent = Agent::connect_within(&args.session, &format!("wheelchair-{}", std::process::id()), timeout)?;
    // Close the agent on every path, errors included: the last process of a session removes
    // its files, even when the hub died first.
    let result = drive(&mut agent, args);
    agent.close();
    result
}

fn drive(agent: &mut Agent, args: &WheelchairArgs) -> anyhow::Result<ExitCode> {
    let mut ids = Vec::new();
    for k in 0..args.robots {
        let mut reg = RobotRegistration::new(&format!("{}{}", args.name, k + 1));
        reg.requested_id = if args.id > 0 { args.id + k as u32 } else { 0 };
        reg.width_m = args.width;
        reg.height_m = args.height;
        reg.com = args.com;
        reg.max_speed_mps = args.max_speed;
        reg.accel_curve = args.accel_curve;
        if let Some([x, y, dir]) = args.pose {
            reg.flags |= REG_HAS_POSE;
            reg.pose = [x + args.spacing * (k % 10) as f64, y + args.spacing * (k / 10) as f64, dir];
        }
        ids.push(agent.register(&reg)?);
    }
    agent.ready()?;
    eprintln!("iwsim agent wheelchair: agent {} drives robots {:?} in session {:?}", agent.id(), ids, args.session);
    let actions: Vec<ActionBlock> =
        ids.iter().map(|&id| ActionBlock::motors(id, args.powers[0], args.powers[1])).collect();
    let wait = if args.busy_poll { Wait::BusyPoll } else { Wait::Blocking };
    let mut answered = 0u64;
    let mut latencies_ns = Vec::new();
    while let Some(tick) = agent.wait_tick(wait)? {
        let t = tick.tick;
        agent.send(t, &actions)?;
        if args.report_latency {
            latencies_ns.push(tick.latency_ns);
        }
        answered += 1;
        if args.ticks > 0 && answered >= args.ticks {
            break;
        }
    }
    eprintln!("iwsim agent wheelchair: answered {answered} ticks");
    if args.report_latency {
        // The first ticks include connection set-up; they are not the steady state.
        let steady = latencies_ns.get(latencies_ns.len().min(100)..).unwrap_or(&[]);
        println!("{}", crate::bench::Percentiles::of_ns(steady).json());
    }
    Ok(ExitCode::SUCCESS)
}
