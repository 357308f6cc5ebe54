//! A push commanded over the WebSocket, from the command to the verdict, each step off the
//! control loop and off the async workers: [`prepare`] locates the particle in a quick local
//! scan and plans the move; [`launch`] hands each push of it to the loop; [`judge`] scans after
//! each push and decides, or launches a correction. Each uses only those before it in the order
//! launch, judge, prepare.

pub mod judge;
pub mod launch;
pub mod prepare;
