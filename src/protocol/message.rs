//! Tells a decoded frame's direction: host command or device reply.
//!
//! Both directions share the standard layout. A reply's can_id has a zero low
//! byte (`(index << 16) | (dev_id << 8)`), and no command's can_id does
//! (control 0x01..0x9F/0xFF, jog 0xF0, config 0xA0), so the can_id decides.

use super::command::Command;
use super::error::ProtocolError;
use super::frame::Frame;
use super::reply::Reply;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Message {
    Command(Command),
    Reply(Reply),
}

impl Message {
    pub fn from_frame(frame: &Frame) -> Result<Message, ProtocolError> {
        if let Frame::Standard(sf) = frame {
            if let Some(reply) = Reply::from_standard(sf) {
                return Ok(Message::Reply(reply));
            }
        }
        Command::from_frame(frame).map(Message::Command)
    }

    pub fn to_frame(&self) -> Frame {
        match self {
            Message::Command(c) => c.to_frame(),
            Message::Reply(r) => r.to_frame(),
        }
    }
}
