//! The Hand-E register map (manual §4.4), as pure functions. Each 16-bit register
//! holds two gripper bytes, byte 0 in the high half.

use crate::gripper::{GripperCommand, ObjectStatus};

/// First output (robot → gripper) register.
pub const OUTPUT_BASE: u16 = 0x03E8;
/// First input (gripper → robot) register.
pub const INPUT_BASE: u16 = 0x07D0;
/// Registers in each block (6 bytes).
pub const BLOCK_LEN: u16 = 3;
/// Factory slave id.
pub const DEFAULT_SLAVE: u8 = 9;
/// Baud rate (8N1).
pub const BAUD: u32 = 115_200;

/// ACTION bit: activate.
pub const R_ACT: u8 = 0x01;
/// ACTION bit: go to the requested position.
pub const R_GTO: u8 = 0x08;
/// ACTION bit: automatic (emergency) release.
pub const R_ATR: u8 = 0x10;

/// The output registers for an action byte and a move.
#[must_use]
pub fn encode_output(action: u8, cmd: GripperCommand) -> [u16; 3] {
    [
        u16::from(action) << 8,
        u16::from(cmd.position),
        (u16::from(cmd.speed) << 8) | u16::from(cmd.force),
    ]
}

/// Action byte and move from output registers (the gripper's side).
pub fn decode_output(regs: &[u16]) -> Result<(u8, GripperCommand), String> {
    let [r0, r1, r2] = regs else {
        return Err(format!("expected 3 output registers, found {}", regs.len()));
    };
    Ok((
        (r0 >> 8) as u8,
        GripperCommand {
            position: (r1 & 0xFF) as u8,
            speed: (r2 >> 8) as u8,
            force: (r2 & 0xFF) as u8,
        },
    ))
}

/// The input registers, decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RawStatus {
    /// gACT: activation echo.
    pub g_act: bool,
    /// gGTO: go-to echo.
    pub g_gto: bool,
    /// gSTA: 0 reset, 1 activating, 3 active.
    pub g_sta: u8,
    /// gOBJ: 0 moving, 1 contact opening, 2 contact closing, 3 at position.
    pub g_obj: u8,
    /// gFLT, the gripper's fault code (low nibble of the fault byte).
    pub g_flt: u8,
    /// kFLT, the controller's fault code (high nibble of the fault byte).
    pub k_flt: u8,
    /// gPR requested position echo.
    pub g_pr: u8,
    /// gPO actual position.
    pub g_po: u8,
    /// gCU current, about 10 mA per count.
    pub g_cu: u8,
}

impl RawStatus {
    /// The STATUS byte (byte 0).
    #[must_use]
    pub const fn status_byte(&self) -> u8 {
        (self.g_act as u8)
            | ((self.g_gto as u8) << 3)
            | ((self.g_sta & 3) << 4)
            | ((self.g_obj & 3) << 6)
    }

    /// The FAULT byte (byte 2): kFLT in the high nibble, gFLT in the low one.
    #[must_use]
    pub const fn fault_byte(&self) -> u8 {
        ((self.k_flt & 0x0F) << 4) | (self.g_flt & 0x0F)
    }

    /// Encode to the three input registers.
    #[must_use]
    pub fn encode(&self) -> [u16; 3] {
        [
            u16::from(self.status_byte()) << 8,
            (u16::from(self.fault_byte()) << 8) | u16::from(self.g_pr),
            (u16::from(self.g_po) << 8) | u16::from(self.g_cu),
        ]
    }

    /// Activated and ready.
    #[must_use]
    pub const fn active(&self) -> bool {
        self.g_act && self.g_sta == 3
    }

    /// Object detection as the trait reports it.
    #[must_use]
    pub const fn object(&self) -> ObjectStatus {
        match self.g_obj & 3 {
            0 => ObjectStatus::Moving,
            1 => ObjectStatus::ContactOpening,
            2 => ObjectStatus::ContactClosing,
            _ => ObjectStatus::AtPosition,
        }
    }
}

/// Decode the three input registers; any other count is an error (never a panic).
pub fn decode_status(regs: &[u16]) -> Result<RawStatus, String> {
    let [r0, r1, r2] = regs else {
        return Err(format!("expected 3 status registers, found {}", regs.len()));
    };
    let s = (r0 >> 8) as u8;
    Ok(RawStatus {
        g_act: s & 0x01 != 0,
        g_gto: s & 0x08 != 0,
        g_sta: (s >> 4) & 0x03,
        g_obj: (s >> 6) & 0x03,
        g_flt: ((r1 >> 8) as u8) & 0x0F,
        k_flt: ((r1 >> 8) as u8) >> 4,
        g_pr: (r1 & 0xFF) as u8,
        g_po: (r2 >> 8) as u8,
        g_cu: (r2 & 0xFF) as u8,
    })
}

/// How serious a gFLT code is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FaultClass {
    /// No fault.
    None,
    /// 0x05 wait for activation, 0x07 rACT not set (a command out of order).
    Priority,
    /// 0x08 over-temperature, 0x09 no communication for 1 s: clear on their own.
    Minor,
    /// 0x0A–0x0F: need a new activation edge (rACT 0 then 1).
    Major,
    /// A code the manual does not list (treated like a major fault).
    Unknown,
}

/// The class of a fault byte (kFLT << 4 | gFLT). Any controller fault (kFLT ≠ 0)
/// is [`FaultClass::Unknown`]: the Hand-E manual leaves its codes to the controller's
/// manual, so the gripper is treated as needing a new activation.
#[must_use]
pub const fn fault_class(code: u8) -> FaultClass {
    if code >> 4 != 0 {
        return FaultClass::Unknown;
    }
    match code {
        0 => FaultClass::None,
        0x05 | 0x07 => FaultClass::Priority,
        0x08 | 0x09 => FaultClass::Minor,
        0x0A..=0x0F => FaultClass::Major,
        _ => FaultClass::Unknown,
    }
}

/// What a gFLT code (the low nibble of the fault byte) means, by the Hand-E manual's
/// names.
#[must_use]
pub const fn fault_text(code: u8) -> &'static str {
    match code & 0x0F {
        0 => "no fault",
        0x05 => "action delayed: activation must complete first",
        0x07 => "the activation bit must be set first",
        0x08 => "maximum operating temperature exceeded",
        0x09 => "no communication for at least 1 s",
        0x0A => "under minimum operating voltage",
        0x0B => "automatic release in progress",
        0x0C => "internal fault",
        0x0D => "activation fault",
        0x0E => "overcurrent",
        0x0F => "automatic release completed",
        _ => "unknown fault",
    }
}

/// A fault byte in words for errors and events: the gFLT by name and code, and the
/// kFLT by code when the controller reports one.
#[must_use]
pub fn describe_fault(byte: u8) -> String {
    let (k, g) = (byte >> 4, byte & 0x0F);
    let gripper = format!("gFLT 0x{g:02X} ({})", fault_text(g));
    if k == 0 {
        gripper
    } else {
        format!(
            "{gripper}, controller fault kFLT 0x{k:X} (a code of the Robotiq controller, listed in its own manual)"
        )
    }
}

/// Modbus RTU CRC-16 (polynomial 0xA001 reflected, initial 0xFFFF); sent low byte first.
#[must_use]
pub fn crc16(bytes: &[u8]) -> u16 {
    let mut crc: u16 = 0xFFFF;
    for &b in bytes {
        crc ^= u16::from(b);
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0xA001
            } else {
                crc >> 1
            };
        }
    }
    crc
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn manual_examples_decode() {
        // Activation complete: 0x3100 (gACT, gSTA = 3).
        let s = decode_status(&[0x3100, 0, 0]).expect("3 regs");
        assert!(s.active() && s.g_flt == 0);
        // 0xB9: object detected while closing; 0xF9: at requested position.
        assert_eq!(
            decode_status(&[0xB900, 0, 0]).expect("3").object(),
            ObjectStatus::ContactClosing
        );
        assert_eq!(
            decode_status(&[0xF900, 0, 0]).expect("3").object(),
            ObjectStatus::AtPosition
        );
        // Close: 09 00 00 FF FF FF.
        let cmd = GripperCommand {
            position: 0xFF,
            speed: 0xFF,
            force: 0xFF,
        };
        assert_eq!(encode_output(R_ACT | R_GTO, cmd), [0x0900, 0x00FF, 0xFFFF]);
        assert_eq!(decode_output(&[0x0900, 0x00FF, 0xFFFF]), Ok((0x09, cmd)));
        // CRC of "01 03 00 00 00 01" is 0x0A84 (sent 84 0A).
        assert_eq!(crc16(&[0x01, 0x03, 0x00, 0x00, 0x00, 0x01]), 0x0A84);
        assert!(decode_status(&[1, 2]).is_err());
        assert_eq!(fault_class(0x0E), FaultClass::Major);
        assert_eq!(fault_class(0x08), FaultClass::Minor);
    }

    #[test]
    fn the_fault_byte_splits_into_gflt_and_kflt_and_both_are_named() {
        // 0x5E: controller fault 5, gripper overcurrent.
        let s = decode_status(&[0x3100, 0x5E00, 0]).expect("3 regs");
        assert_eq!((s.g_flt, s.k_flt, s.fault_byte()), (0x0E, 0x05, 0x5E));
        assert_eq!(fault_class(s.fault_byte()), FaultClass::Unknown);
        assert_eq!(fault_class(0x0E), FaultClass::Major);
        let text = describe_fault(0x5E);
        assert!(
            text.contains("gFLT 0x0E (overcurrent)") && text.contains("kFLT 0x5"),
            "{text}"
        );
        assert_eq!(
            describe_fault(0x05),
            "gFLT 0x05 (action delayed: activation must complete first)"
        );
        assert_eq!(describe_fault(0x03), "gFLT 0x03 (unknown fault)");
        assert_eq!(fault_class(0x03), FaultClass::Unknown);
    }

    #[test]
    fn status_round_trips() {
        let s = RawStatus {
            g_act: true,
            g_gto: true,
            g_sta: 3,
            g_obj: 2,
            g_flt: 0x0E,
            k_flt: 0x3,
            g_pr: 200,
            g_po: 180,
            g_cu: 40,
        };
        assert_eq!(decode_status(&s.encode()), Ok(s));
    }
}
